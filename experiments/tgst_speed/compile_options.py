"""TGST transfer: XLA compiler options per executable against the default, interleaved rounds, paired ratios."""
import os, pathlib, sys, time, json
import jax, jax.numpy as jnp, numpy as np
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))
from benchmarks.cases import peers as P
from benchmarks.cases import tgst as T
from jaxgest.tgst import model as M
b = int(sys.argv[1]); variants = json.loads(sys.argv[2]); rounds = int(os.environ.get("R", 11))
cfg = P.TCFG; params = P.tgst_params(); c, s = T._clips(b, 1280)
f = jax.jit(lambda p, c, s: M.transfer_arrays(p, c, s, cfg=cfg, method="soft")[:2])
lo = f.lower(params, c, s)
fns = {"default": lo.compile()}
for name, opts in variants.items():
    try:
        fns[name] = lo.compile(compiler_options=opts)
    except Exception as e:
        print(name, "failed:", str(e)[:200]); continue
ref = jax.block_until_ready(fns["default"](params, c, s))
for k, fn in fns.items():
    out = jax.block_until_ready(fn(params, c, s))
    print(k, "max|diff| %.2e" % max(float(np.abs(np.asarray(a) - np.asarray(r)).max()) for a, r in zip(out, ref)))
inner = 5 if b > 1 else 20
W = {k: [] for k in fns}; C = {k: [] for k in fns}
for rnd in range(rounds):
    for k, fn in fns.items():
        t0 = time.perf_counter(); q0 = time.process_time()
        for _ in range(inner): jax.block_until_ready(fn(params, c, s))
        W[k].append((time.perf_counter() - t0) / inner); C[k].append((time.process_time() - q0) / inner)
for k in fns:
    r = np.array(W["default"]) / np.array(W[k]); rc = np.array(C["default"]) / np.array(C[k])
    print("%-28s wall med %.2f min %.2f cpu %.2f | default/this wall %.2f+-%.2f cpu %.2f+-%.2f" % (
        k, 1e3 * np.median(W[k]), 1e3 * min(W[k]), 1e3 * np.median(C[k]), r.mean(), r.std(ddof=1) / np.sqrt(len(r)), rc.mean(), rc.std(ddof=1) / np.sqrt(len(r))))
print("load", os.getloadavg())

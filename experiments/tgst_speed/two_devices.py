"""TGST transfer b8: one device vs the batch split over 2 host devices (same process, interleaved rounds)."""
import os, pathlib, sys, time
os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
import jax, jax.numpy as jnp, numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P_
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))
from benchmarks.cases import peers as P
from benchmarks.cases import tgst as T
from jaxgest.tgst import model as M
b = int(sys.argv[1]) if len(sys.argv) > 1 else 8
cfg = P.TCFG
params = P.tgst_params()
c, s = T._clips(b, 1280)
def f(params, content, style):
    u, l, _ = M.transfer_arrays(params, content, style, cfg=cfg, method="soft")
    return u, l
d0 = jax.devices()[0]
f1 = jax.jit(f)
p1, c1, s1 = jax.device_put((params, c, s), d0)
mesh = Mesh(np.array(jax.devices()[:2]), ("data",))
rep, bat = NamedSharding(mesh, P_()), NamedSharding(mesh, P_("data"))
f2 = jax.jit(f, in_shardings=(rep, bat, bat), out_shardings=(bat, bat))
p2, c2, s2 = jax.device_put(params, rep), jax.device_put(c, bat), jax.device_put(s, bat)
ref = jax.block_until_ready(f1(p1, c1, s1)); out = jax.block_until_ready(f2(p2, c2, s2))
print("max|diff|", max(float(np.abs(np.asarray(a) - np.asarray(r)).max()) for a, r in zip(out, ref)))
W = {"1dev": [], "2dev": []}; C = {"1dev": [], "2dev": []}
for rnd in range(11):
    for name, fn, args in (("1dev", f1, (p1, c1, s1)), ("2dev", f2, (p2, c2, s2))):
        t0 = time.perf_counter(); q0 = time.process_time()
        for _ in range(5): jax.block_until_ready(fn(*args))
        W[name].append((time.perf_counter() - t0) / 5); C[name].append((time.process_time() - q0) / 5)
for k in W: print(k, "wall median ms %.2f min %.2f cpu %.2f" % (1e3 * np.median(W[k]), 1e3 * min(W[k]), 1e3 * np.median(C[k])))
r = np.array(W["1dev"]) / np.array(W["2dev"]); print("paired wall ratio 1dev/2dev %.2f +- %.2f" % (r.mean(), r.std(ddof=1) / np.sqrt(len(r))), "load", os.getloadavg())

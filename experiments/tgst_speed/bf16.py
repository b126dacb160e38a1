"""TGST transfer b8: fp32 jit vs bf16 (params + inputs cast) jit, interleaved rounds, wall + CPU time."""
import os, pathlib, sys, time
import jax, jax.numpy as jnp, numpy as np
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
    return u.astype(jnp.float32), l.astype(jnp.float32)
f32 = jax.jit(f)
cast = lambda t: jax.tree.map(lambda x: x.astype(jnp.bfloat16) if x.dtype == jnp.float32 else x, t)
pb, cb, sb = cast(params), cast(c), cast(s)
fb = jax.jit(f)
t0=time.perf_counter(); ref = jax.block_until_ready(f32(params, c, s)); print("compile f32", time.perf_counter()-t0)
t0=time.perf_counter(); out = jax.block_until_ready(fb(pb, cb, sb)); print("compile bf16", time.perf_counter()-t0)
for a, r in zip(out, ref):
    a, r = np.asarray(a), np.asarray(r)
    print("max|diff|", np.abs(a-r).max(), "rms", np.sqrt(((a-r)**2).mean()), "ref range", np.ptp(r, axis=(0,1)).mean())
W = {"f32": [], "bf16": []}; C = {"f32": [], "bf16": []}
for rnd in range(9):
    for name, fn, args in (("f32", f32, (params, c, s)), ("bf16", fb, (pb, cb, sb))):
        t0 = time.perf_counter(); p0 = time.process_time()
        for _ in range(3): jax.block_until_ready(fn(*args))
        W[name].append((time.perf_counter()-t0)/3); C[name].append((time.process_time()-p0)/3)
for k in W: print(k, "wall median ms %.2f min %.2f cpu %.2f" % (1e3*np.median(W[k]), 1e3*min(W[k]), 1e3*np.median(C[k])))
r = np.array(C["f32"])/np.array(C["bf16"]); print("cpu ratio f32/bf16 %.2f +- %.2f" % (r.mean(), r.std()/len(r)**.5))
print("wall ratio", np.median(W["f32"])/np.median(W["bf16"]), "load", os.getloadavg())

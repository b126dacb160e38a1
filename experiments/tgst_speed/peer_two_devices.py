"""Peer TGST case with an extra impl: the batch split over 2 host devices (same process, interleaved)."""
import os, pathlib, sys
os.environ["XLA_FLAGS"] = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
import jax, numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P_
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))
from benchmarks import harness as H
from benchmarks.cases import peers
from jaxgest.tgst import model as M
H.configure_jax()
b = int(sys.argv[1]); cfg = peers.TCFG
case = peers.tgst_case(b, with_torch=os.environ.get("NO_TORCH") != "1")  # NO_TORCH=1: the two jit impls alone
mesh = Mesh(np.array(jax.devices()[:2]), ("data",))
rep, bat = NamedSharding(mesh, P_()), NamedSharding(mesh, P_("data"))
def f(params, content, style):
    return M.transfer_arrays(params, content, style, cfg=cfg, method="soft")[:2]
case.impls = list(case.impls) + [H.Impl("jit_2dev", jax.jit(f, in_shardings=(rep, bat, bat), out_shardings=(bat, bat)), kind="jit")]
recs = H.run_case(case, repeats=int(os.environ.get("R", 9)), log=lambda s: None)
for r in recs: print(r["impl"], "median ms %.2f min %.2f cpu %.2f" % (r["median_us"]/1e3, r["min_us"]/1e3, r["cpu_median_us"]/1e3))
torch_t = [r["median_us"] for r in recs if r["impl"].startswith("torch")]
for r in recs:
    if r["impl"].startswith("jit") and torch_t: print(r["impl"], "vs best torch %.2fx" % (min(torch_t) / r["median_us"]))
print("load", os.getloadavg())

"""The peer benchmark's TGST case (`jaxgest.bench.cases.peers.tgst_case`, its harness and interleaved rounds)
with one more implementation: the batch split over 2 host devices.

    python peer_two_devices.py BATCH        (env R: repeats, default 9; NO_TORCH=1: the two jit impls alone)
"""
import os
import sys

os.environ["XLA_FLAGS"] = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
import jax  # noqa: E402
import numpy as np  # noqa: E402
from jax.sharding import Mesh, NamedSharding, PartitionSpec  # noqa: E402

from common import transfer_case  # noqa: E402  (puts the repository on the path)
from jaxgest.bench import harness as H  # noqa: E402
from jaxgest.bench.cases import peers  # noqa: E402

H.configure_jax()
b = int(sys.argv[1])
case = peers.tgst_case(b, with_torch=os.environ.get("NO_TORCH") != "1")
f = transfer_case(b)[-1]
mesh = Mesh(np.array(jax.devices()[:2]), ("data",))
rep, bat = NamedSharding(mesh, PartitionSpec()), NamedSharding(mesh, PartitionSpec("data"))
case.impls = list(case.impls) + [
    H.Impl("jit_2dev", jax.jit(f, in_shardings=(rep, bat, bat), out_shardings=(bat, bat)), kind="jit")]
recs = H.run_case(case, repeats=int(os.environ.get("R", 9)), log=lambda s: None)
for r in recs:
    print(r["impl"], "median ms %.2f min %.2f cpu %.2f" % (r["median_us"] / 1e3, r["min_us"] / 1e3,
                                                          r["cpu_median_us"] / 1e3))
torch_t = [r["median_us"] for r in recs if r["impl"].startswith("torch")]
for r in recs:
    if r["impl"].startswith("jit") and torch_t:
        print(r["impl"], "vs best torch %.2fx" % (min(torch_t) / r["median_us"]))
print("load", os.getloadavg())

"""TGST transfer: one device vs the batch split over 2 host devices (same process, interleaved rounds).

    python two_devices.py [BATCH]
"""
import os
import sys

os.environ["XLA_FLAGS"] = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
import jax  # noqa: E402
import numpy as np  # noqa: E402
from jax.sharding import Mesh, NamedSharding, PartitionSpec  # noqa: E402

from common import interleaved, max_diff, transfer_case  # noqa: E402

params, content, style, f = transfer_case(int(sys.argv[1]) if len(sys.argv) > 1 else 8)
one = jax.device_put((params, content, style), jax.devices()[0])
mesh = Mesh(np.array(jax.devices()[:2]), ("data",))
rep, bat = NamedSharding(mesh, PartitionSpec()), NamedSharding(mesh, PartitionSpec("data"))
f1 = jax.jit(f)
f2 = jax.jit(f, in_shardings=(rep, bat, bat), out_shardings=(bat, bat))
two = (jax.device_put(params, rep), jax.device_put(content, bat), jax.device_put(style, bat))
print("max|diff|", max_diff(f2(*two), f1(*one)))
interleaved({"1dev": lambda: f1(*one), "2dev": lambda: f2(*two)})

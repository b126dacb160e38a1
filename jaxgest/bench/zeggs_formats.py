"""Weight formats of the ZeroEGGS generator against its fp32 jit, interleaved rounds (no torch needed).

``python -m jaxgest.bench.zeggs_formats [BATCH]`` (env ``T`` generated frames, default 60; ``ROUNDS``, default
7): the paper preset with the benchmark's random weights, ``fp32`` (the model, jit), ``bf16``, ``int8``
(with its C++ kernel at batch <= 4 when available, rows split over XLA's intra-op pool), ``int8_1t`` (the
kernel on the calling thread only) and ``int8_xla`` (the same params traced with the kernel switched off),
timed in interleaved rounds; prints the median wall and process-CPU time per frame, their
ratios against fp32, the max |pose difference| against fp32 and the load average.
"""

from __future__ import annotations

import os
import sys
import time

import jax
import numpy as np

from jaxgest.bench.cases import peers
from jaxgest.bench.cases import zeggs as Z
from jaxgest.kernels import int8_kernel


def main(batch: int = 1, frames: int = 60, rounds: int = 7) -> dict:
    args = Z.generator_inputs(Z.CFG, batch, frames, seed=0)
    gen, gen_1t, gen_xla = (jax.jit(Z._generate_fn(Z.CFG)) for _ in range(3))
    impls = {"fp32": (gen, Z._params()), "bf16": (gen, peers._quantized("bf16")),
             "int8": (gen, peers._quantized("int8")), "int8_1t": (gen_1t, peers._quantized("int8")),
             "int8_xla": (gen_xla, peers._quantized("int8"))}
    kernel = int8_kernel.available()
    ref = np.asarray(gen(Z._params(), *args)["pose"])
    diff = {}
    outs = {}
    for name, (f, p) in impls.items():
        # trace (and compile) int8_xla with the kernel off, int8_1t with one worker; later calls reuse them
        if name == "int8_xla":
            int8_kernel.available = lambda: False
        if name == "int8_1t":
            int8_kernel.threads = lambda: 1
        try:
            outs[name] = np.asarray(f(p, *args)["pose"])
            diff[name] = float(np.max(np.abs(outs[name] - ref)))
        finally:
            int8_kernel.available, int8_kernel.threads = available, threads
    if kernel:
        print(f"int8 kernel: pose of 2 workers == 1 worker bit for bit: "
              f"{bool(np.array_equal(outs['int8'], outs['int8_1t']))}")
    wall = {k: [] for k in impls}
    cpu = {k: [] for k in impls}
    load0 = os.getloadavg()
    for _ in range(rounds):
        for name, (f, p) in impls.items():
            t, c = time.perf_counter(), time.process_time()
            jax.block_until_ready(f(p, *args))
            wall[name].append((time.perf_counter() - t) / frames * 1e3)
            cpu[name].append((time.process_time() - c) / frames * 1e3)
    w0, c0 = np.median(wall["fp32"]), np.median(cpu["fp32"])
    print(f"batch {batch}, {frames} frames, {rounds} interleaved rounds; int8 kernel available: {kernel}")
    for name in impls:
        w, c = np.median(wall[name]), np.median(cpu[name])
        print(f"  {name:9s} wall {w:8.2f} ms/frame (fp32/this {w0 / w:.2f}x)  CPU {c:8.2f} ms/frame "
              f"({c0 / c:.2f}x)  max |diff| vs fp32 {diff[name]:.4f}")
    print(f"load average (1, 5, 15 min) before {load0}, after {os.getloadavg()}")
    return {"wall": wall, "cpu": cpu, "diff": diff}


available, threads = int8_kernel.available, int8_kernel.threads

if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1, int(os.environ.get("T", 60)),
         int(os.environ.get("ROUNDS", 7)))

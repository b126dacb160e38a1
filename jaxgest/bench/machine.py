"""The machine context of a benchmark run: what the numbers were measured on.

* :func:`probe_machine`: peak float32 GEMM rate and memory bandwidth of the moment (a ~1-second probe);
* :func:`floor`: a call's compute / memory floor against that probe;
* :func:`machine_info`: CPU, cores, library versions, XLA flags, torch threads.
"""

from __future__ import annotations

import os
import platform
import time
from typing import Optional

import jax
import numpy as np

from jaxgest.runtime import provenance


def probe_machine(seconds: float = 1.0, *, gemm_n: int = 1024, stream_mb: int = 128) -> dict:
    """Peak float32 GEMM rate and memory read bandwidth of the moment, ~``seconds`` in total (XLA, all cores).

    GEMM: a jitted ``gemm_n`` x ``gemm_n`` float32 matmul, repeated for half the time, best call ->
    ``gemm_gflops`` (2 n^3 / s). Bandwidth: a jitted matrix-vector product over a ``stream_mb`` MB float32
    matrix (too large for any cache; the access pattern of batch-1 generation), repeated for the other
    half, best call -> ``mem_gbps`` (matrix bytes / s; XLA CPU's plain reductions stream slower than its
    dot). The best call of a short window is what the machine could give then; on a shared machine both
    move with the load.
    """
    import jax.numpy as jnp

    a = jnp.asarray(np.random.default_rng(0).normal(size=(gemm_n, gemm_n)), jnp.float32)
    mm = jax.jit(lambda x, y: x @ y).lower(a, a).compile()
    x = jnp.ones((stream_mb * 2**20 // 4 // 4096, 4096), jnp.float32)
    v = jnp.ones((1, x.shape[0]), jnp.float32)
    mv = jax.jit(lambda v, x: v @ x).lower(v, x).compile()

    def best(f, budget):
        jax.block_until_ready(f())
        out, t_end = [], time.perf_counter() + budget
        while time.perf_counter() < t_end or len(out) < 3:
            t = time.perf_counter()
            jax.block_until_ready(f())
            out.append(time.perf_counter() - t)
        return min(out)

    t0 = time.perf_counter()
    gemm = 2.0 * gemm_n ** 3 / best(lambda: mm(a, a), seconds / 2) / 1e9
    bw = x.size * 4 / best(lambda: mv(v, x), seconds / 2) / 1e9
    return {"gemm_gflops": gemm, "mem_gbps": bw, "probe_s": time.perf_counter() - t0,
            "load_avg_1m": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}


def floor(flops: float, nbytes: float, seconds: float, probe: dict) -> dict:
    """The compute / memory floor of a call: ``{"floor_bound", "floor_fraction"}``.

    floor = max(flops / GEMM peak, bytes / bandwidth) of the probe; fraction = floor / measured time (1 =
    at the machine's limit; nulls without a probe).
    """
    if not probe or seconds <= 0:
        return {"floor_bound": None, "floor_fraction": None}
    t_c = flops / (probe["gemm_gflops"] * 1e9)
    t_m = nbytes / (probe["mem_gbps"] * 1e9)
    return {"floor_bound": "compute" if t_c >= t_m else "memory", "floor_fraction": max(t_c, t_m) / seconds}


def machine_info(probe: Optional[dict] = None) -> dict:
    """CPU model, core count, versions and XLA flags: the context a number needs (``probe``: this run's
    :func:`probe_machine`)."""
    cpu = provenance.cpu_model()
    import jaxlib

    try:
        affinity = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        affinity = None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "cores_usable": affinity,
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "numpy": np.__version__,
        "backend": jax.default_backend(),
        "devices": jax.device_count(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        # Thread settings of the NumPy BLAS; load average: other processes on the machine make every
        # number noisier (a 1-minute load above the core count means the timings are shared).
        "thread_env": {k: os.environ[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
                       if k in os.environ},
        "load_avg_1m": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "persistent_compilation_cache": bool(jax.config.jax_enable_compilation_cache
                                             and jax.config.jax_compilation_cache_dir),
        # XLA's CPU client runs one intra-op thread pool over every core the process may use
        "xla_cpu_threads": affinity or os.cpu_count(),
        "torch": _torch_info(),
        "probe": dict(probe) if probe else None,
    }


def _torch_info() -> Optional[dict]:
    """torch version and intra-op threads when the suite imported torch (the PyTorch peers), else None."""
    import sys

    torch = sys.modules.get("torch")
    if torch is None:
        return None
    return {"version": torch.__version__, "threads": torch.get_num_threads()}

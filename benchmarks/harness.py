"""Timing harness: trace / lower / compile separately from steady state, warm-up, repeats, peak memory.

A :class:`Case` is one workload (name, batch, frames) with several :class:`Impl` implementations of the
same computation on the same weights (``jit``, ``eager``, ``numpy`` ...). :func:`run_case` first checks
that every implementation produces the same output as the first one (``check_equal``: a benchmark that
times a wrong implementation is worse than none), then times each:

* jit impls (``kind="jit"``): ``jax.jit(f).trace(*args)``, ``.lower()``, ``.compile()`` are timed one by
  one (``trace_s``, ``lower_s``, ``compile_s``), then the compiled executable runs in steady state;
* other impls: steady state only.

Steady state: ``warmup`` calls, then ``repeats`` timed repeats; each repeat runs the call ``inner`` times
(chosen so a repeat lasts at least ``min_repeat_s``) and records the time per call. Outputs are waited
for with ``jax.block_until_ready``. Reported: ``min_us`` and ``median_us`` per call and
``per_pose_us = median_us / poses`` (poses = batch x frames unless the case says otherwise).

Peak memory: the process's resident-set high-water mark (Linux ``VmHWM``), reset before each
implementation through ``/proc/self/clear_refs`` ("5"), so ``peak_rss_mb`` is the peak RSS of the process
while that implementation was compiled and run (it includes what the process already held: compare
between rows, not as an absolute model size). ``None`` where the kernel does not allow the reset.
"""

from __future__ import annotations

import dataclasses
import os
import platform
import statistics
import time
from typing import Any, Callable, Optional, Sequence

import jax
import numpy as np

RECORD_FIELDS = {
    "case": str,
    "impl": str,
    "batch": int,
    "frames": int,
    "per_pose_us": float,
    "compile_s": (float, type(None)),
    "repeats": int,
    "min_us": float,
    "median_us": float,
}
EXTRA_FIELDS = {
    "trace_s": (float, type(None)),
    "lower_s": (float, type(None)),
    "inner": int,
    "poses": int,
    "peak_rss_mb": (float, type(None)),
    "max_abs_diff": (float, type(None)),
    "group": str,
    "note": str,
}


class EqualityError(AssertionError):
    """Two implementations of a case disagree: the case is not timed."""


@dataclasses.dataclass
class Impl:
    """One implementation: ``fn(*args)``; ``kind`` is ``"jit"`` (AOT-timed) or anything else."""

    name: str
    fn: Callable
    kind: str = "plain"


@dataclasses.dataclass
class Case:
    """A workload and its implementations. ``args`` is built lazily (``make_args()``) once per case.

    ``group`` names a family of cases plotted together (e.g. per-pose cost against clip length).
    ``poses`` defaults to batch x frames. ``rtol``/``atol`` are the equality tolerances.
    """

    name: str
    batch: int
    frames: int
    impls: Sequence[Impl]
    make_args: Callable[[], tuple]
    poses: Optional[int] = None
    rtol: float = 1e-4
    atol: float = 1e-4
    group: str = ""
    note: str = ""
    quick: bool = True  # part of --quick
    max_repeats_slow: int = 3  # for impls slower than ~1 s per call

    @property
    def num_poses(self) -> int:
        return self.poses if self.poses is not None else self.batch * self.frames


def _to_numpy_tree(x):
    return jax.tree_util.tree_map(lambda a: np.asarray(a, dtype=np.float64), x)


def check_equal(outputs: dict, *, rtol: float, atol: float) -> dict:
    """Compare every output pytree with the first; raise :class:`EqualityError` naming the impl that differs.

    Returns ``{impl: max_abs_diff}``.
    """
    names = list(outputs)
    ref = _to_numpy_tree(outputs[names[0]])
    ref_leaves, ref_def = jax.tree_util.tree_flatten(ref)
    diffs = {names[0]: 0.0}
    for name in names[1:]:
        leaves, tree_def = jax.tree_util.tree_flatten(_to_numpy_tree(outputs[name]))
        if tree_def != ref_def:
            raise EqualityError(f"{name}: output structure differs from {names[0]}")
        worst = 0.0
        for a, b in zip(ref_leaves, leaves):
            if a.shape != b.shape:
                raise EqualityError(f"{name}: output shape {b.shape} differs from {names[0]}'s {a.shape}")
            if not np.allclose(b, a, rtol=rtol, atol=atol):
                bad = float(np.max(np.abs(b - a)))
                raise EqualityError(
                    f"{name}: output differs from {names[0]} (max abs diff {bad:.3g} > atol {atol} + rtol {rtol})"
                )
            worst = max(worst, float(np.max(np.abs(b - a))) if a.size else 0.0)
        diffs[name] = worst
    return diffs


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _peak_rss_mb() -> Optional[float]:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def _block(x):
    return jax.block_until_ready(x)


def time_steady(call: Callable[[], Any], *, repeats: int, warmup: int = 2, min_repeat_s: float = 0.02,
                max_inner: int = 10_000) -> tuple[list[float], int]:
    """Per-call seconds of ``repeats`` repeats (after ``warmup`` calls) and the inner loop count used."""
    t0 = time.perf_counter()
    for _ in range(max(warmup, 1)):
        _block(call())
    single = (time.perf_counter() - t0) / max(warmup, 1)
    inner = int(min(max_inner, max(1, np.ceil(min_repeat_s / max(single, 1e-9)))))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(inner):
            out = call()
        _block(out)
        times.append((time.perf_counter() - t) / inner)
    return times, inner


def measure(impl: Impl, args: tuple, *, repeats: int, warmup: int = 2, min_repeat_s: float = 0.02) -> dict:
    """Time one implementation; returns the timing fields of a record."""
    tracked = _reset_peak()
    rec: dict = {"trace_s": None, "lower_s": None, "compile_s": None}
    if impl.kind == "jit":
        jitted = impl.fn if hasattr(impl.fn, "trace") else jax.jit(impl.fn)
        # The equality check already compiled this computation: drop the in-memory caches so the
        # trace / lower / compile times below are those of a first call. (A persistent compilation
        # cache, if configured, would still shorten compile_s; the suite reports it as measured.)
        jax.clear_caches()
        t0 = time.perf_counter()
        traced = jitted.trace(*args)
        t1 = time.perf_counter()
        lowered = traced.lower()
        t2 = time.perf_counter()
        compiled = lowered.compile()
        t3 = time.perf_counter()
        rec.update(trace_s=t1 - t0, lower_s=t2 - t1, compile_s=t3 - t2)

        def call():
            return compiled(*args)
    else:

        def call():
            return impl.fn(*args)

    # Very slow implementations (eager JAX at large sizes) get fewer repeats; the rule is recorded.
    t = time.perf_counter()
    _block(call())
    first = time.perf_counter() - t
    if first > 1.0:
        repeats = max(2, min(repeats, 3))
        warmup = 0
    times, inner = time_steady(call, repeats=repeats, warmup=warmup, min_repeat_s=min_repeat_s)
    rec.update(
        repeats=len(times),
        inner=inner,
        min_us=min(times) * 1e6,
        median_us=statistics.median(times) * 1e6,
        peak_rss_mb=_peak_rss_mb() if tracked else None,
    )
    return rec


def run_case(case: Case, *, repeats: int = 7, impls: Optional[Sequence[str]] = None, check: bool = True,
             log: Callable[[str], None] = print) -> list[dict]:
    """Check the implementations agree, then time each; one record per implementation."""
    args = case.make_args()
    chosen = [i for i in case.impls if impls is None or i.name in impls]
    diffs = {}
    if check and len(chosen) > 1:
        outputs = {}
        for impl in chosen:
            fn = jax.jit(impl.fn) if impl.kind == "jit" and not hasattr(impl.fn, "trace") else impl.fn
            outputs[impl.name] = jax.device_get(fn(*args))
        diffs = check_equal(outputs, rtol=case.rtol, atol=case.atol)
    records = []
    for impl in chosen:
        rec = {
            "case": case.name,
            "impl": impl.name,
            "batch": case.batch,
            "frames": case.frames,
            "poses": case.num_poses,
            "group": case.group,
            "note": case.note,
            "max_abs_diff": diffs.get(impl.name),
        }
        rec.update(measure(impl, args, repeats=repeats))
        rec["per_pose_us"] = rec["median_us"] / case.num_poses
        log(f"  {case.name:<34} {impl.name:<8} {rec['median_us'] / 1e3:10.3f} ms/call  "
            f"{rec['per_pose_us']:9.4f} us/pose  compile {rec['compile_s'] or 0:.2f} s")
        records.append(rec)
    return records


def validate_record(rec: dict) -> None:
    """Raise ValueError when a record does not follow the SPEC §8 schema (plus the extra fields)."""
    for key, typ in RECORD_FIELDS.items():
        if key not in rec:
            raise ValueError(f"record misses {key!r}: {rec}")
        if not isinstance(rec[key], typ) or isinstance(rec[key], bool):
            raise ValueError(f"record field {key!r} has type {type(rec[key]).__name__}: {rec}")
    for key, typ in EXTRA_FIELDS.items():
        if key in rec and not isinstance(rec[key], typ):
            raise ValueError(f"record field {key!r} has type {type(rec[key]).__name__}")
    if rec["median_us"] < rec["min_us"] or rec["min_us"] <= 0:
        raise ValueError(f"record times are inconsistent: {rec}")


def machine_info() -> dict:
    """CPU model, core count, versions and XLA flags: the context a number needs."""
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import jaxlib

    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "numpy": np.__version__,
        "backend": jax.default_backend(),
        "devices": jax.device_count(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }

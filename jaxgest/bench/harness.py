"""Timing harness: trace / lower / compile separately from steady state, warm-up, repeats, peak memory.

A :class:`Case` is one workload (name, batch, frames) with several :class:`Impl` implementations of the
same computation on the same weights (``jit``, ``eager``, ``numpy`` ...). :func:`run_case` first prepares
every implementation (:func:`prepare`: compile, one call) and checks that it produces the same output as
the first one (:func:`check_equal`; no steady state is timed when they disagree -- a benchmark that times
a wrong implementation is worse than none), then times each:

* jit impls (``kind="jit"``): the in-memory JAX caches are cleared, then ``jax.jit(f).trace(*args)``,
  ``.lower()`` and ``.compile()`` are timed one by one (``trace_s``, ``lower_s``, ``compile_s``), and the
  resulting ``Compiled`` executable gives the output of the equality check and runs in steady state (one
  compilation per implementation). The persistent compilation cache is switched off by
  :func:`configure_jax` (``python -m benchmarks`` calls it) so ``compile_s`` is a real compile, not a disk
  read;
* compiled non-JAX impls (``kind="compiled"``: ``torch.compile``): the first call compiles; its wall time is
  reported as ``compile_s`` (it includes that one call's run), then steady state as for the others;
* other impls (eager JAX under ``jax.disable_jit()``, NumPy, ...): steady state only, ``compile_s`` null.

An implementation may name its own ``reference`` (e.g. ``torch.compile`` checked against the eager peer);
otherwise it is checked against the case's first implementation.

Work of a call (the floor fraction, :func:`jaxgest.bench.machine.floor`): the case's ``work`` function, or
else XLA's cost analysis of the case's first jit implementation (``xla_flops``; the same count is used for
every implementation of the case) with the compulsory bytes = the arguments and outputs of one call.

Steady state: warm-up calls (at least one: eager JAX caches one executable per primitive on first use),
then ``repeats`` timed repeats. Each repeat runs the call ``inner`` times, ``inner`` chosen so a repeat
lasts at least ``min_repeat_s`` (20 ms) and the per-call time is recorded; every call's output is waited
for with ``jax.block_until_ready`` before the next call starts, so the number is the latency of one call,
not the throughput of overlapping asynchronous dispatches. Implementations slower than the per-impl
budget get fewer repeats (never fewer than 2); ``repeats`` in the record is what was actually run.
Reported: ``min_us`` and ``median_us`` per call, ``per_pose_us = median_us / poses`` (poses = batch x
frames unless the case says otherwise) and ``per_frame_us = median_us / frames`` (the cost of one frame of
the whole batch: the per-step latency of an autoregressive generator). ``cpu_median_us`` is the median
process CPU time per call (all threads): on a loaded machine the wall-clock numbers stretch with the
load while the CPU time of single-threaded work barely moves, so comparing the two tells a slow
implementation from a busy machine (CPU / wall ~ 2 on an idle 2-core machine running both cores).

Peak memory (Linux): the kernel's resident-set high-water mark is reset (``/proc/self/clear_refs`` <- "5")
before an implementation is prepared and again before its steady state. ``peak_rss_mb`` is the larger
``VmHWM`` of the two phases -- the peak RSS of the whole process while that implementation was traced,
compiled and run -- and ``peak_mem_mb`` the larger increase over the RSS at the start of each phase (what
the implementation added at its peak: compiled code, buffers, temporaries; the inputs and weights, built
before, are not counted). Both are ``None`` where the reset is not allowed.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
import time
from typing import Any, Callable, Optional, Sequence

import jax
import numpy as np

from jaxgest.bench.machine import floor
from jaxgest.bench.records import (DOCUMENT_FIELDS, EXTRA_FIELDS, RECORD_FIELDS,  # noqa: F401  (re-exported)
                                    validate_document, validate_record)


class EqualityError(AssertionError):
    """Two implementations of a case disagree: the case is not timed."""


@dataclasses.dataclass
class Impl:
    """One implementation: ``fn(*args)``; ``kind="jit"`` gets trace / lower / compile timed apart.

    For ``kind="jit"``, ``fn`` is either a ``jax.jit``-wrapped function (static arguments already bound)
    or a plain function that the harness wraps in ``jax.jit``.
    """

    name: str
    fn: Callable
    kind: str = "plain"
    # equality tolerances of this implementation against the reference (None: the case's); e.g. a
    # reduced-precision variant checked loosely
    rtol: Optional[float] = None
    atol: Optional[float] = None
    # the implementation whose output this one's is checked against (None: the case's first)
    reference: Optional[str] = None


@dataclasses.dataclass
class Case:
    """A workload and its implementations. ``make_args()`` builds the inputs (and weights) once.

    ``group`` names a family of cases plotted together (per-pose cost against clip length).
    ``poses`` defaults to batch x frames. ``rtol``/``atol`` are the equality tolerances (``np.allclose``
    semantics, in float64). ``quick`` marks cases that are part of ``--quick``.
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
    quick: bool = True
    max_repeats_slow: int = 3  # repeats for impls slower than ~1 s per call
    # time the implementations in interleaved rounds (A B A B ...; median of rounds): a fair ratio on a
    # machine whose load changes during the run
    interleave: bool = False
    # work of one call of an implementation: ``work(impl_name) -> (flops, bytes)`` (the compulsory memory
    # traffic), for the floor fraction (:func:`floor`)
    work: Optional[Callable[[str], tuple]] = None
    # flops XLA's cost analysis leaves out (it counts a while loop's body once, :func:`xla_cost`):
    # ``uncounted_flops() -> flops`` is added to the jit's count for the work of a call (without ``work``)
    uncounted_flops: Optional[Callable[[], float]] = None

    @property
    def num_poses(self) -> int:
        return self.poses if self.poses is not None else self.batch * self.frames


def configure_jax() -> None:
    """Benchmark settings: no persistent compilation cache (compile_s must be a real compile)."""
    jax.config.update("jax_enable_compilation_cache", False)


def _as_jitted(impl: Impl):
    return impl.fn if hasattr(impl.fn, "trace") else jax.jit(impl.fn)


def _to_numpy_tree(x):
    return jax.tree_util.tree_map(lambda a: np.asarray(a, dtype=np.float64), x)


def check_equal(outputs: dict, *, rtol: float, atol: float, tolerances: Optional[dict] = None,
                references: Optional[dict] = None) -> dict:
    """Compare every output pytree with the first one's (or ``references[name]``'s); ``{impl: max_abs_diff}``.

    Raises :class:`EqualityError` naming the implementation that differs (structure, shape, values) or
    the reference when its output is not finite (NaN == NaN would hide a broken case).
    """
    names = list(outputs)
    first = names[0]
    rtol0, atol0 = rtol, atol
    for path, a in jax.tree_util.tree_flatten_with_path(_to_numpy_tree(outputs[first]))[0]:
        if not np.all(np.isfinite(a)):
            raise EqualityError(f"{first}: output{jax.tree_util.keystr(path)} is not finite")
    diffs = {first: 0.0}
    for name in names[1:]:
        ref_name = (references or {}).get(name) or first
        if ref_name not in outputs:
            raise EqualityError(f"{name}: its reference {ref_name!r} was not run")
        ref_leaves, ref_def = jax.tree_util.tree_flatten_with_path(_to_numpy_tree(outputs[ref_name]))
        rtol, atol = (tolerances or {}).get(name, (rtol0, atol0))
        leaves, tree_def = jax.tree_util.tree_flatten_with_path(_to_numpy_tree(outputs[name]))
        if tree_def != ref_def:
            raise EqualityError(f"{name}: output structure {tree_def} differs from {ref_name}'s {ref_def}")
        worst = 0.0
        for (path, a), (_, b) in zip(ref_leaves, leaves):
            where = f"output{jax.tree_util.keystr(path)}"
            if a.shape != b.shape:
                raise EqualityError(f"{name}: {where} shape {b.shape} differs from {ref_name}'s {a.shape}")
            if not np.allclose(b, a, rtol=rtol, atol=atol):
                err = np.abs(b - a)
                bad = float(np.nanmax(err)) if np.any(np.isfinite(err)) else float("nan")
                raise EqualityError(
                    f"{name}: {where} differs from {ref_name}'s (max abs diff {bad:.3g}, "
                    f"{int(np.sum(~np.isclose(b, a, rtol=rtol, atol=atol)))} of {a.size} values outside "
                    f"atol {atol:g} + rtol {rtol:g})"
                )
            worst = max(worst, float(np.max(np.abs(b - a))) if a.size else 0.0)
        diffs[name] = worst
    return diffs


def _status_mb(key: str) -> Optional[float]:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def _reset_peak() -> Optional[float]:
    """Reset the RSS high-water mark; return the current RSS in MB, or None when not possible."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return None
    return _status_mb("VmRSS")


def time_steady(call: Callable[[], Any], *, repeats: int, warmup: int = 2, min_repeat_s: float = 0.02,
                budget_s: float = float("inf"), max_inner: int = 10_000,
                cpu_times: Optional[list] = None) -> tuple[list[float], int]:
    """Per-call seconds of the timed repeats (after ``warmup`` untimed calls) and the inner count used.

    The warm-up calls also estimate one call's cost, which fixes ``inner`` (a repeat lasts at least
    ``min_repeat_s``) and caps the repeats so their total stays within ``budget_s`` (at least 2).
    ``cpu_times``, when given, receives the per-call process CPU seconds (all threads) of each repeat.
    """
    warm = []
    for _ in range(max(warmup, 1)):
        t = time.perf_counter()
        jax.block_until_ready(call())
        warm.append(time.perf_counter() - t)
    single = max(min(warm), 1e-9)
    inner = int(min(max_inner, max(1, math.ceil(min_repeat_s / single))))
    repeats = max(2, min(repeats, int(budget_s // (single * inner))))
    times = []
    for _ in range(repeats):
        c = time.process_time()
        t = time.perf_counter()
        for _ in range(inner):
            jax.block_until_ready(call())
        times.append((time.perf_counter() - t) / inner)
        if cpu_times is not None:
            cpu_times.append((time.process_time() - c) / inner)
    return times, inner


@dataclasses.dataclass
class Prepared:
    """An implementation ready to be timed (see :func:`prepare`)."""

    call: Callable[[], Any]  # one call on the case's arguments (the compiled executable for jit impls)
    timings: dict  # trace_s / lower_s / compile_s (None for non-jit impls)
    first_call_s: float  # seconds of the first call (slow implementations get fewer repeats)
    rss0: Optional[float]  # RSS (MB) before tracing, None where the high-water mark cannot be reset
    peak: Optional[float]  # RSS high-water mark (MB) after compiling and the first call
    cost: Optional[dict] = None  # jit: XLA's cost analysis of the executable (flops, bytes accessed)


def prepare(impl: Impl, args: tuple) -> tuple[Prepared, Any]:
    """Compile (jit: trace / lower / compile timed apart) and call once; returns it and the first output.

    The in-memory JAX caches are cleared first, so the three times are those of a first call even when
    the same function was compiled before (the persistent cache is off, see :func:`configure_jax`).
    """
    rss0 = _reset_peak()
    timings: dict = {"trace_s": None, "lower_s": None, "compile_s": None}
    if impl.kind == "jit":
        jitted = _as_jitted(impl)
        jax.clear_caches()
        t0 = time.perf_counter()
        traced = jitted.trace(*args)
        t1 = time.perf_counter()
        lowered = traced.lower()
        t2 = time.perf_counter()
        compiled = lowered.compile()
        t3 = time.perf_counter()
        timings.update(trace_s=t1 - t0, lower_s=t2 - t1, compile_s=t3 - t2)
        cost = xla_cost(compiled)

        def call():
            return compiled(*args)
    else:
        cost = None

        def call():
            return impl.fn(*args)

    t = time.perf_counter()
    out = jax.block_until_ready(call())
    first = time.perf_counter() - t
    if impl.kind == "compiled":  # torch.compile & co: the first call traces and compiles
        timings["compile_s"] = first
    peak = _status_mb("VmHWM") if rss0 is not None else None
    return Prepared(call, timings, first, rss0, peak, cost), out


def xla_cost(compiled) -> Optional[dict]:
    """``{"flops", "bytes_accessed"}`` of a compiled JAX executable (XLA's HLO cost analysis), or None.

    XLA counts a while loop's body once, whatever its trip count: a ``lax.scan`` over T steps is
    undercounted T-fold, so cases with scans give their own ``work`` count."""
    try:
        c = compiled.cost_analysis()
    except Exception:  # noqa: BLE001  (backends without cost analysis)
        return None
    if isinstance(c, (list, tuple)):
        c = c[0] if c else None
    if not c or "flops" not in c:
        return None
    return {"flops": float(c["flops"]), "bytes_accessed": float(c.get("bytes accessed", 0.0))}


def tree_nbytes(tree) -> float:
    """Bytes of the array leaves of a pytree (numpy, JAX or anything with ``nbytes``)."""
    return float(sum(getattr(x, "nbytes", 0) for x in jax.tree_util.tree_leaves(tree)))


def measure(impl: Impl, args: tuple, *, repeats: int, warmup: int = 2, min_repeat_s: float = 0.02,
            budget_s: float = 20.0, slow_repeats: int = 3, prepared: Optional[Prepared] = None) -> dict:
    """Time one implementation (after :func:`prepare`, done here unless given); timing and memory fields."""
    if prepared is None:
        prepared, _ = prepare(impl, args)
    rec: dict = dict(prepared.timings)
    # The first call tells slow implementations (eager JAX on long clips) apart: one warm-up and fewer
    # repeats for those, so the suite stays within its time budget.
    if prepared.first_call_s > 1.0:
        repeats, warmup = min(repeats, slow_repeats), 0
    rss_run = _reset_peak() if prepared.rss0 is not None else None
    cpu: list = []
    times, inner = time_steady(prepared.call, repeats=repeats, warmup=warmup, min_repeat_s=min_repeat_s,
                               budget_s=budget_s, cpu_times=cpu)
    peak = peak_mem = None
    if prepared.rss0 is not None and rss_run is not None:
        peak_run = _status_mb("VmHWM")
        peak = max(prepared.peak, peak_run)
        peak_mem = max(0.0, prepared.peak - prepared.rss0, peak_run - rss_run)
    rec.update(
        repeats=len(times),
        inner=inner,
        min_us=min(times) * 1e6,
        median_us=statistics.median(times) * 1e6,
        cpu_median_us=statistics.median(cpu) * 1e6,
        peak_rss_mb=peak,
        peak_mem_mb=peak_mem,
    )
    return rec


def run_case(case: Case, *, repeats: int = 7, impls: Optional[Sequence[str]] = None, check: bool = True,
             budget_s: float = 20.0, log: Callable[[str], None] = print, probe: Optional[dict] = None) -> list[dict]:
    """Prepare every implementation (compile, one call), check they agree, then time each; one record each.

    ``probe``: this run's :func:`jaxgest.bench.machine.probe_machine`, for each record's floor fraction (nulls
    without one).

    Raises :class:`EqualityError` (before any steady-state timing) when an implementation disagrees.
    """
    args = case.make_args()
    chosen = [i for i in case.impls if impls is None or i.name in impls]
    compare = check and len(chosen) > 1
    prepared: dict = {}
    outputs: dict = {}
    io_bytes = None
    for impl in chosen:
        prepared[impl.name], out = prepare(impl, args)
        if io_bytes is None and impl.kind == "jit":
            io_bytes = tree_nbytes(args) + tree_nbytes(out)
        if compare:
            outputs[impl.name] = jax.device_get(out)
        del out
    tolerances = {i.name: (case.rtol if i.rtol is None else i.rtol, case.atol if i.atol is None else i.atol)
                  for i in chosen}
    references = {i.name: i.reference for i in chosen if i.reference and i.reference in outputs}
    diffs: dict = (check_equal(outputs, rtol=case.rtol, atol=case.atol, tolerances=tolerances,
                               references=references) if compare else {})
    del outputs
    jit_cost = next((prepared[i.name].cost for i in chosen if prepared[i.name].cost), None)
    timed = (time_interleaved({i.name: prepared.pop(i.name) for i in chosen}, repeats=repeats)
             if case.interleave and len(chosen) > 1 else {})
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
            "reference": references.get(impl.name, chosen[0].name if compare and impl is not chosen[0] else None),
            "xla_flops": jit_cost["flops"] if jit_cost else None,
            "xla_bytes_accessed": jit_cost["bytes_accessed"] if jit_cost else None,
        }
        if timed:
            rec.update(timed[impl.name], interleaved=True)
        else:
            rec.update(measure(impl, args, repeats=repeats, budget_s=budget_s,
                               slow_repeats=case.max_repeats_slow, prepared=prepared.pop(impl.name)))
        rec["per_pose_us"] = rec["median_us"] / case.num_poses
        rec["per_frame_us"] = rec["median_us"] / case.frames
        work = (case.work(impl.name) if case.work is not None
                else (jit_cost["flops"] + (case.uncounted_flops() if case.uncounted_flops else 0.0), io_bytes)
                if jit_cost and io_bytes is not None else None)
        if work is not None:
            flops, nbytes = work
            rec.update(flops=float(flops), bytes=float(nbytes))
            rec.update(floor(flops, nbytes, rec["median_us"] * 1e-6, probe))
        log(f"  {case.name:<28} {impl.name:<6} {rec['median_us'] / 1e3:10.3f} ms/call "
            f"{rec['per_pose_us']:10.4f} us/pose  compile {rec['compile_s'] or 0:5.2f} s  x{rec['repeats']}")
        records.append(rec)
    return records


def time_interleaved(prepared: dict, *, repeats: int, warmup: int = 2, min_repeat_s: float = 0.02) -> dict:
    """Time several prepared implementations in interleaved rounds: A B C, A B C, ... (``repeats`` rounds).

    Each implementation first gets ``warmup`` untimed calls, which fix its ``inner`` count (a repeat lasts
    at least ``min_repeat_s``); then every round times one repeat of each, in turn, so a change of the
    machine's load hits all of them alike. Returns ``{name: timing fields}`` (median and min of the rounds).
    """
    calls, inner = {}, {}
    for name, p in prepared.items():
        warm = []
        for _ in range(max(warmup, 1)):
            t = time.perf_counter()
            jax.block_until_ready(p.call())
            warm.append(time.perf_counter() - t)
        calls[name] = p.call
        inner[name] = int(max(1, math.ceil(min_repeat_s / max(min(warm), 1e-9))))
    times: dict = {n: [] for n in calls}
    cpu: dict = {n: [] for n in calls}
    for _ in range(repeats):
        for name, call in calls.items():
            c = time.process_time()
            t = time.perf_counter()
            for _ in range(inner[name]):
                jax.block_until_ready(call())
            times[name].append((time.perf_counter() - t) / inner[name])
            cpu[name].append((time.process_time() - c) / inner[name])
    out = {}
    for name, p in prepared.items():
        out[name] = dict(p.timings, repeats=len(times[name]), inner=inner[name],
                         min_us=min(times[name]) * 1e6, median_us=statistics.median(times[name]) * 1e6,
                         cpu_median_us=statistics.median(cpu[name]) * 1e6,
                         peak_rss_mb=p.peak, peak_mem_mb=(None if p.rss0 is None else max(0.0, p.peak - p.rss0)))
    return out

"""Shared training machinery: TrainState, the one update step, metrics.jsonl, the loop.

Every model (TGST autoencoder, TGST transformer, ZEGGS) trains through :func:`train_loop`:

* the step is ``(state, batch, key) -> (state, metrics)``, jit-compiled once with the state donated;
* the batch for step ``i`` is a pure function of ``(seed, i)`` (``batch_fn(i)``), so a run killed at any
  point and resumed from its last checkpoint ends with exactly the parameters of an uninterrupted run;
* checkpoints are :class:`jaxgest.runtime.checkpoint.Checkpointer` (orbax, with a stored and checked model config;
  re-exported here with the workdir format checks);
* ``workdir/metrics.jsonl`` gets one JSON line per log step and ``workdir/config.json`` the config; a line's
  training metrics are their means over the steps since the previous line (of this run: the first line after a
  resume averages the steps since the resume), accumulated on the device; ``MetricsLogger(tb_dir=...)`` writes
  the same scalars for TensorBoard (:class:`TensorBoardWriter`, tensorboardX: the ``[tb]`` extra);
* ``eval_fn`` / ``eval_every``: a held-out loss at every log step that is a multiple of ``eval_every`` (and
  the last), logged on that line with the prefix ``eval_``; ``profile_dir``: :data:`PROFILE_STEPS` steps
  after the first (compiling) one of the run traced with :func:`jax.profiler.trace` (TensorBoard's profile
  plugin or Perfetto read the trace);
* SIGINT / SIGTERM (Ctrl-C, a batch scheduler's or a preemptible machine's notice) finish the current step,
  save a checkpoint of that step and stop with :class:`~jaxgest.runtime.errors.Interrupted` (the command line prints its
  one line, e.g. ``runs/a: tgst transformer interrupted by SIGTERM at step 137; checkpoint saved at step 137
  (run the same command to resume)``, and exits 130 / 143); a second signal exits at once, keeping the previous
  checkpoint (:func:`stop_on_signals`). Processes of a multi-process run agree on the step to save;
* a non-finite loss stops training with :class:`~jaxgest.runtime.errors.TrainingError`, keeping the last good
  checkpoint (nothing is saved after the bad step). Metrics are checked at every log or checkpoint step,
  and the parameters before every save (a NaN gradient with a still-finite loss is caught there), e.g.
  ``tgst autoencoder: non-finite loss at step 120; stopped, the last good checkpoint (step 100) is kept
  (lower the learning rate or check the data for NaN)``.

References: big_vision train loop; flax examples' orbax usage.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import pathlib
import signal
import sys
import threading
import time
from typing import Any, Callable, Mapping, Optional

import jax
import jax.numpy as jnp
import numpy as np
from flax.training.train_state import TrainState  # noqa: F401  (re-exported: the state every step uses)

from jaxgest.runtime.checkpoint import Checkpointer, all_finite, strict_checkpoints, warn  # noqa: F401  (re-exported)
from jaxgest.runtime.workdir_format import (FORMAT_VERSION, MODELS, check_workdir_config,  # noqa: F401  (re-exported)
                                    config_diff)
from jaxgest.runtime.errors import DataError, Interrupted, JaxgestError, TrainingError, WriteError
from jaxgest.runtime.io import write_error, write_json_atomic  # noqa: F401  (write_json_atomic re-exported)

__all__ = [
    "TrainState",
    "make_update_step",
    "bare_state",
    "jit_config_step",
    "Checkpointer",
    "MetricsLogger",
    "TensorBoardWriter",
    "heldout_eval",
    "train_loop",
    "stop_on_signals",
    "StopRequest",
    "config_diff",
    "write_json_atomic",
    "FORMAT_VERSION",
    "check_workdir_config",
    "MODELS",
    "strict_checkpoints",
    "warn",
]


LossFn = Callable[[Any, Any, jax.Array, jax.Array], tuple[jax.Array, Mapping[str, jax.Array]]]


def make_update_step(loss_fn: LossFn, *, fold_in_step: bool = False):
    """The one optimiser step every model trains with: ``step(state, batch, key) -> (state, metrics)``.

    ``loss_fn(params, batch, key, step) -> (loss, metrics)`` is differentiated with respect to ``params``
    and the state's own optimiser (``state.tx``) applies the gradients (``TrainState.apply_gradients``:
    ``step + 1``, new params and optimiser state). With ``fold_in_step`` the key is first folded with the
    step count, so a stochastic loss (dropout, sampling) draws fresh noise every step from one run key.
    The returned function is pure; :func:`jaxgest.runtime.parallel.parallelize_step` jits it with the state donated.
    """

    def step(state: TrainState, batch, key: jax.Array):
        if fold_in_step:
            key = jax.random.fold_in(key, state.step)
        grads, metrics = jax.grad(loss_fn, has_aux=True)(state.params, batch, key, state.step)
        return state.apply_gradients(grads=grads), metrics

    return step


def bare_state(state: TrainState) -> TrainState:
    """``state`` without its static fields (optimiser object, apply function): params, opt_state, step.

    A TrainState's ``tx`` and ``apply_fn`` are static fields, i.e. part of jit's cache key, and a fresh
    ``optax`` optimiser per ``train`` call would never match it; a step given to :func:`jit_config_step`
    takes and returns the bare state and rebuilds its optimiser from the (static) config inside.
    """
    return state.replace(apply_fn=None, tx=None)


def jit_config_step(step: Callable, mesh, cfg, *, extra_args: int = 0,
                    compiler_options: Optional[dict] = None) -> Callable:
    """``step(state, batch, key, *extra, cfg) -> (state, metrics)`` jit-compiled data-parallel over ``mesh``
    with ``cfg`` (a frozen, hashable config) a static argument, bound: returns ``(state, batch, key, *extra)
    -> (state, metrics)`` with the shardings of :func:`jaxgest.runtime.parallel.parallelize_step` (state, key and the
    ``extra_args`` further arguments replicated, batch split, state donated).

    ``step`` must be a module-level function and ``state`` a :func:`bare_state`: the cache key is then
    (step, config, shapes, shardings, compiler options) and jit's own cache serves every training of one
    config in a process (resume, tests) without tracing again; nothing is memoised here.
    """
    from jaxgest.runtime import parallel

    rep, data = parallel.replicated(mesh), parallel.data_sharding(mesh)
    jitted = jax.jit(step, in_shardings=(rep, data, rep) + (rep,) * extra_args, out_shardings=(rep, rep),
                     static_argnums=(3 + extra_args,), donate_argnums=(0,), compiler_options=compiler_options)
    return lambda state, batch, key, *extra: jitted(state, batch, key, *extra, cfg)


#: steps traced by ``train_loop(profile_dir=...)`` (``--profile DIR``), after the run's first (compiling) step
PROFILE_STEPS = 3
#: prefix of held-out metrics in metrics.jsonl (``eval_loss``, ...)
EVAL_PREFIX = "eval_"
#: held-out batches of one evaluation: the same ones every time, so that the curve compares like with like
EVAL_BATCHES = 4
#: seed of the held-out batches and noise (not the run's: runs of other seeds see the same batches)
EVAL_SEED = 0x5EED


def heldout_eval(metrics_fn: Callable, batches, *args) -> Callable[[Any], dict]:
    """``eval_fn(state)`` for :func:`train_loop`: the mean over ``batches`` (fixed, built once) of
    ``metrics_fn(state.params, batch, state.step, *args) -> {name: scalar}`` (jit-compiled by the caller)."""
    batches = list(batches)
    if not batches:
        raise ValueError("heldout_eval: no batches")

    def eval_fn(state) -> dict:
        total = None
        for b in batches:
            m = metrics_fn(state.params, b, state.step, *args)
            total = m if total is None else _tree_add(total, m)
        return {k: v / len(batches) for k, v in total.items()}

    return eval_fn


class TensorBoardWriter:
    """The scalars of every :meth:`log` call as TensorBoard events (tensorboardX, the ``[tb]`` extra):
    training metrics in ``tb_dir/train``, held-out ones (``eval_...``, the prefix dropped) in
    ``tb_dir/eval``, so that TensorBoard draws the two runs of one tag (``<stage>/loss``) in one chart.
    Flushed at every call."""

    def __init__(self, tb_dir, stage: Optional[str] = None):
        try:
            from tensorboardX import SummaryWriter
        except ImportError:
            raise JaxgestError("--tb needs tensorboardX: pip install 'jaxgest[tb]' "
                               "(or pip install tensorboardX)") from None
        self.dir = pathlib.Path(tb_dir)
        if self.dir.exists() and not self.dir.is_dir():
            raise WriteError(f"{self.dir}: --tb needs a folder, and this is a file")
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise write_error(self.dir, e, existed=False) from None
        self.stage = stage
        self._writers = {run: SummaryWriter(str(self.dir / run)) for run in ("train", "eval")}

    def log(self, step: int, metrics: Mapping[str, Any]) -> None:
        used = set()
        for k, v in metrics.items():
            if not isinstance(v, (int, float)) or isinstance(v, bool):
                continue
            run, name = ("eval", k[len(EVAL_PREFIX):]) if k.startswith(EVAL_PREFIX) else ("train", k)
            tag = f"{self.stage}/{name}" if self.stage else name
            self._writers[run].add_scalar(tag, float(v), int(step))
            used.add(run)
        for run in used:
            self._writers[run].flush()

    def close(self) -> None:
        for w in self._writers.values():
            w.close()


class MetricsLogger:
    """Appends one JSON object per log step to ``workdir/metrics.jsonl`` and, with ``tb_dir``, writes the
    metrics for TensorBoard too (:class:`TensorBoardWriter`, tagged with ``extra["stage"]``)."""

    def __init__(self, workdir, filename: str = "metrics.jsonl", extra: Optional[Mapping] = None,
                 tb_dir=None):
        self.path = pathlib.Path(workdir) / filename
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.extra = dict(extra or {})
        self.tb = TensorBoardWriter(tb_dir, stage=self.extra.get("stage")) if tb_dir is not None else None

    def close(self) -> None:
        if self.tb is not None:
            self.tb.close()

    def log(self, step: int, metrics: Mapping[str, Any]) -> dict:
        record = {"step": int(step), **self.extra}
        for k, v in metrics.items():
            v = np.asarray(jax.device_get(v))
            record[k] = float(v) if v.ndim == 0 else v.tolist()
        line = json.dumps(record, sort_keys=True) + "\n"
        size = self.path.stat().st_size if self.path.exists() else 0
        try:
            with open(self.path, "a") as f:
                f.write(line)
        except OSError as e:  # disk full, read-only: no half line is left behind
            with contextlib.suppress(OSError):
                os.truncate(self.path, size)
            raise write_error(self.path, e, existed=size > 0) from None
        if self.tb is not None:
            self.tb.log(step, {k: record[k] for k in metrics})
        return record


def _kept(checkpointer: Optional["Checkpointer"]) -> str:
    last = checkpointer.latest_step() if checkpointer is not None else None
    return "no checkpoint was written" if last is None else f"the last good checkpoint (step {last}) is kept"


_HINT = "(lower the learning rate or check the data for NaN)"


def _check_finite(step: int, metrics: Mapping[str, float], stage: str, checkpointer=None) -> None:
    bad = [k for k, v in metrics.items() if isinstance(v, float) and not math.isfinite(v)]
    if bad:
        raise TrainingError(f"{stage}: non-finite {', '.join(sorted(bad))} at step {step}; stopped, "
                            f"{_kept(checkpointer)} {_HINT}")


def _check_params(step: int, params, stage: str, checkpointer) -> None:
    """Before a save: the loss of a step is computed before its update, so a NaN/inf gradient with a finite
    loss would otherwise be checkpointed."""
    if not bool(jax.device_get(all_finite(params))):
        raise TrainingError(f"{stage}: non-finite parameters at step {step} (NaN/inf gradient); stopped, "
                            f"{_kept(checkpointer)} {_HINT}")


def check_intervals(**intervals) -> None:
    """Raise :class:`TrainingError` unless every given interval (``log_every=50, ...``; None = default) is a
    positive whole number of steps."""
    for name, value in intervals.items():
        if value is not None and not (isinstance(value, (int, np.integer)) and value >= 1):
            raise TrainingError(f"{name} must be a positive number of steps, got {value!r}")


def check_eval(eval_data, eval_every, log_every) -> None:
    """Raise :class:`TrainingError` unless ``eval_data`` and ``eval_every`` come together, ``eval_every`` is a
    multiple of ``log_every`` (a held-out loss is logged on a log line) and ``eval_data`` is a folder."""
    if (eval_data is None) != (eval_every is None):
        raise TrainingError("--eval-every and --eval-data go together: the held-out loss needs held-out "
                            "clips (--eval-data DIR) and an interval (--eval-every N)")
    if eval_every is None:
        return
    check_intervals(eval_every=eval_every)
    if log_every is not None and eval_every % log_every:
        raise TrainingError(f"--eval-every {eval_every} must be a multiple of --log-every {log_every} "
                            "(the held-out loss is logged on a log line)")
    if not pathlib.Path(eval_data).is_dir():
        raise DataError(f"{eval_data}: --eval-data needs a folder of held-out clips, and there is none")


def check_steps(**counts) -> None:
    """Raise :class:`TrainingError` if a given step count (None = default) is negative."""
    for name, value in counts.items():
        if value is not None and int(value) < 0:
            raise TrainingError(f"{name} must be >= 0, got {value}")


class StopRequest:
    """What :func:`stop_on_signals` yields: the first stop signal received (``signum``, None until one is) and,
    for the message of a second one, what is being done (``doing``, set by the training loop)."""

    def __init__(self):
        self.signum: Optional[int] = None
        self.doing: str = ""

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name if self.signum is not None else ""


def _second_signal_line(request: StopRequest, signum: int) -> str:
    doing = f" {request.doing}" if request.doing else ""
    return (f"jaxgest: {signal.Signals(signum).name} again{doing}: stopped at once; the previous checkpoint "
            "is kept (an unfinished save is removed by the next run)\n")


@contextlib.contextmanager
def stop_on_signals(signals=(signal.SIGINT, signal.SIGTERM)):
    """Within this context the first of ``signals`` only records itself in the yielded :class:`StopRequest`
    (the training loop checks it after every step, saves and stops); a second one writes one line to stderr
    and ends the process at once with status 128 + its number (``os._exit``: no cleanup, so a save in progress
    is abandoned and orbax's atomic rename never happens -- the previous checkpoint stays the latest).

    The previous handlers are put back at the end. Outside the main thread (signals cannot be handled there),
    a signal that is ignored (``SIG_IGN``, e.g. SIGINT of a background job) and a handler installed outside
    Python (JAX's preemption notifier of a multi-process run owns SIGTERM; see :func:`_agreed_stop`) are
    left alone.
    """
    request = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield request
        return

    def handler(signum, frame):
        if request.signum is None:
            request.signum = signum
            return
        try:
            sys.__stderr__.write(_second_signal_line(request, signum))
            sys.__stderr__.flush()
        finally:
            os._exit(128 + signum)

    previous = {}
    try:
        for s in signals:
            old = signal.getsignal(s)
            if old is signal.SIG_IGN or old is None:  # ignored, or owned by non-Python code
                continue
            previous[s] = signal.signal(s, handler)
        yield request
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


def _stop_signals() -> tuple:
    """SIGINT and SIGTERM, except SIGTERM in a multi-process run whose JAX preemption notifier handles it (a
    handler installed by C++ code, which Python's ``signal.getsignal`` does not see): the notice then reaches
    the loop through :func:`_agreed_stop`."""
    if jax.process_count() > 1:
        try:
            from jax._src import distributed

            if getattr(distributed.global_state, "preemption_sync_manager", None) is not None:
                return (signal.SIGINT,)
        except ImportError:
            pass
    return (signal.SIGINT, signal.SIGTERM)


def _agreed_stop(request: StopRequest, step: int) -> Optional[int]:
    """The signal to stop at ``step`` on, agreed by every process (None: go on).

    One process: the signal it received. Several (``jax.distributed``): every process sees the same answer at
    the same step -- a signal any process received (a tiny all-gather of the flags each step), or JAX's
    preemption sync point (:func:`jax.experimental.multihost_utils.reached_preemption_sync_point`: when JAX's
    notifier owns SIGTERM, every process reaches it at the same step after any of them was notified).
    """
    if jax.process_count() == 1:
        return request.signum
    from jax.experimental import multihost_utils

    flags = np.asarray(multihost_utils.process_allgather(np.int32(request.signum or 0)))
    received = [int(f) for f in np.ravel(flags) if f]
    if received:
        return min(received)
    with contextlib.suppress(Exception):  # no preemption sync manager (not initialised by jax.distributed)
        if multihost_utils.reached_preemption_sync_point(step):
            return int(signal.SIGTERM)
    return None


def train_loop(
    state,
    step_fn: Callable,
    batch_fn: Callable[[int], Any],
    *,
    key: jax.Array,
    num_steps: int,
    checkpointer: Optional[Checkpointer] = None,
    logger: Optional[MetricsLogger] = None,
    log_every: int = 50,
    ckpt_every: int = 500,
    desc: str = "train",
    progress: bool = True,
    on_log: Optional[Callable[[int, dict], None]] = None,
    eval_fn: Optional[Callable[[Any], Mapping[str, Any]]] = None,
    eval_every: Optional[int] = None,
    profile_dir=None,
):
    """Run ``step_fn`` from ``state.step`` up to ``num_steps`` (resumes from a restored state).

    ``step_fn(state, batch, key) -> (state, metrics)`` is expected to be jit-compiled with the state
    donated and to ``fold_in(key, state.step)`` inside; ``batch_fn(i)`` returns the batch of step ``i``.
    Metrics are summed on the device and fetched only at log steps (no per-step host sync); a log line holds
    their means over the steps since the previous one. ``eval_fn(state) -> metrics`` (a held-out loss) runs at
    the log steps that are multiples of ``eval_every`` and at the last step; its metrics join that line as
    ``eval_<name>``. ``profile_dir``: trace :data:`PROFILE_STEPS` steps after the first with
    :func:`jax.profiler.trace` into that folder.
    """
    from tqdm.auto import tqdm

    check_intervals(log_every=log_every, ckpt_every=ckpt_every, eval_every=eval_every)
    if (eval_fn is None) != (eval_every is None):
        raise ValueError("train_loop: eval_fn and eval_every go together")
    start = int(jax.device_get(state.step))
    if start >= num_steps:
        return state
    bar = tqdm(total=num_steps, initial=start, desc=desc, disable=not progress, dynamic_ncols=True, leave=False)
    last_log_time = time.perf_counter()
    metrics, summed, n_summed = {}, None, 0
    trace = _ProfileWindow(profile_dir, start, num_steps)
    with stop_on_signals(_stop_signals()) as request, trace:
        for i in range(start, num_steps):
            trace.before(i)
            batch = batch_fn(i)
            state, metrics = step_fn(state, batch, key)
            summed = metrics if summed is None else _tree_add(summed, metrics)
            n_summed += 1
            step = i + 1
            trace.after(step, state)
            at_log = step % log_every == 0 or step == num_steps
            at_ckpt = checkpointer is not None and (step % ckpt_every == 0 or step == num_steps)
            if at_log or at_ckpt:
                host = {k: float(np.asarray(jax.device_get(v))) for k, v in metrics.items()}
                _check_finite(step, host, desc, checkpointer)
                if at_log:  # the interval's means (a non-finite step anywhere in it shows here)
                    host = {k: float(np.asarray(jax.device_get(v))) / n_summed for k, v in summed.items()}
                    now = time.perf_counter()
                    rate = n_summed / max(now - last_log_time, 1e-9) if step > start + 1 else 0.0
                    summed, n_summed = None, 0
                    if eval_fn is not None and (step % eval_every == 0 or step == num_steps):
                        held_out = eval_fn(state)  # its time counts in no interval's steps/s
                        host.update({EVAL_PREFIX + k: float(np.asarray(jax.device_get(v)))
                                     for k, v in held_out.items()})
                    _check_finite(step, host, desc, checkpointer)
                    host["steps_per_s"] = rate
                    last_log_time = time.perf_counter()
                    if logger is not None:
                        try:
                            logger.log(step, host)
                        except WriteError as e:
                            raise WriteError(f"{e}; stopped at step {step}, {_kept(checkpointer)}") from None
                    if on_log is not None:
                        on_log(step, host)
                    bar.set_postfix({k: f"{v:.4g}" for k, v in host.items() if k == "loss"})
                if at_ckpt:
                    request.doing = f"during the checkpoint save of step {step}"
                    _check_params(step, state.params, desc, checkpointer)
                    checkpointer.save(state)
                    request.doing = ""
            bar.update(1)
            signum = _agreed_stop(request, step)
            if signum is not None:
                bar.close()
                _stop(state, step, signum, desc, checkpointer, request, saved=at_ckpt)
    bar.close()
    return state


@jax.jit
def _tree_add(a, b):
    return jax.tree.map(jnp.add, a, b)


class _ProfileWindow:
    """Traces steps ``first .. first + PROFILE_STEPS - 1`` (0-based step indices) of a run with
    :func:`jax.profiler.start_trace` into ``folder``; ``first`` is the run's second step (the first compiles),
    or its only one. Used as a context manager so that an exception stops the trace."""

    def __init__(self, folder, start: int, num_steps: int):
        self.folder = None if folder is None else pathlib.Path(folder)
        self.first = start + 1 if num_steps - start > 1 else start
        self.last = min(num_steps, self.first + PROFILE_STEPS)  # 1-based step count at which to stop
        self.active = False

    def before(self, i: int) -> None:
        if self.folder is not None and i == self.first:
            jax.profiler.start_trace(str(self.folder))
            self.active = True

    def after(self, step: int, state) -> None:
        if self.active and step >= self.last:
            jax.block_until_ready(state)  # the traced steps' device work inside the trace
            self._stop()

    def _stop(self) -> None:
        self.active = False
        jax.profiler.stop_trace()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.active:
            self._stop()


def _stop(state, step: int, signum: int, desc: str, checkpointer, request: StopRequest, saved: bool):
    """Save ``state`` (at ``step``) unless it was just saved, then raise :class:`Interrupted`."""
    name = signal.Signals(signum).name
    if checkpointer is None:
        raise Interrupted(f"{desc} interrupted by {name} at step {step}; no checkpoint is written by this "
                          "run", signum)
    if not saved:
        _check_params(step, state.params, desc, checkpointer)  # nothing non-finite is saved
        request.doing = f"during the checkpoint save of step {step}"
        checkpointer.save(state)
        request.doing = ""
    raise Interrupted(f"{checkpointer.workdir}: {desc} interrupted by {name} at step {step}; checkpoint saved "
                      f"at step {step} (run the same command to resume)", signum)


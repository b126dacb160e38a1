"""Shared training machinery: TrainState, the one update step, metrics.jsonl, the loop.

Every model (TGST autoencoder, TGST transformer, ZEGGS) trains through :func:`train_loop`:

* the step is ``(state, batch, key) -> (state, metrics)``, jit-compiled once with the state donated;
* the batch for step ``i`` is a pure function of ``(seed, i)`` (``batch_fn(i)``), so a run killed at any
  point and resumed from its last checkpoint ends with exactly the parameters of an uninterrupted run;
* checkpoints are :class:`jaxgest.checkpoint.Checkpointer` (orbax, with a stored and checked model config;
  re-exported here with the workdir format checks);
* ``workdir/metrics.jsonl`` gets one JSON line per log step and ``workdir/config.json`` the config;
* a non-finite loss stops training with :class:`~jaxgest.errors.TrainingError`, keeping the last good
  checkpoint (nothing is saved after the bad step). Metrics are checked at every log or checkpoint step,
  and the parameters before every save (a NaN gradient with a still-finite loss is caught there), e.g.
  ``tgst autoencoder: non-finite loss at step 120; stopped, the last good checkpoint (step 100) is kept
  (lower the learning rate or check the data for NaN)``.

References: STYLE.md (big_vision train loop, flax examples' orbax usage).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import pathlib
import time
from typing import Any, Callable, Mapping, Optional

import jax
import numpy as np
from flax.training.train_state import TrainState  # noqa: F401  (re-exported: the state every step uses)

from jaxgest.checkpoint import Checkpointer, all_finite, strict_checkpoints, warn  # noqa: F401  (re-exported)
from jaxgest.workdir_format import (FORMAT_VERSION, MODELS, check_workdir_config,  # noqa: F401  (re-exported)
                                    config_diff)
from jaxgest.errors import TrainingError, WriteError
from jaxgest.io import write_error, write_json_atomic  # noqa: F401  (write_json_atomic re-exported)

__all__ = [
    "TrainState",
    "make_update_step",
    "bare_state",
    "jit_config_step",
    "Checkpointer",
    "MetricsLogger",
    "train_loop",
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
    The returned function is pure; :func:`jaxgest.parallel.parallelize_step` jits it with the state donated.
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
    -> (state, metrics)`` with the shardings of :func:`jaxgest.parallel.parallelize_step` (state, key and the
    ``extra_args`` further arguments replicated, batch split, state donated).

    ``step`` must be a module-level function and ``state`` a :func:`bare_state`: the cache key is then
    (step, config, shapes, shardings, compiler options) and jit's own cache serves every training of one
    config in a process (resume, tests) without tracing again; nothing is memoised here.
    """
    from jaxgest import parallel

    rep, data = parallel.replicated(mesh), parallel.data_sharding(mesh)
    jitted = jax.jit(step, in_shardings=(rep, data, rep) + (rep,) * extra_args, out_shardings=(rep, rep),
                     static_argnums=(3 + extra_args,), donate_argnums=(0,), compiler_options=compiler_options)
    return lambda state, batch, key, *extra: jitted(state, batch, key, *extra, cfg)


class MetricsLogger:
    """Appends one JSON object per log step to ``workdir/metrics.jsonl``."""

    def __init__(self, workdir, filename: str = "metrics.jsonl", extra: Optional[Mapping] = None):
        self.path = pathlib.Path(workdir) / filename
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.extra = dict(extra or {})

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


def check_steps(**counts) -> None:
    """Raise :class:`TrainingError` if a given step count (None = default) is negative."""
    for name, value in counts.items():
        if value is not None and int(value) < 0:
            raise TrainingError(f"{name} must be >= 0, got {value}")


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
    prefetch: int = 1,
):
    """Run ``step_fn`` from ``state.step`` up to ``num_steps`` (resumes from a restored state).

    ``step_fn(state, batch, key) -> (state, metrics)`` is expected to be jit-compiled with the state
    donated and to ``fold_in(key, state.step)`` inside; ``batch_fn(i)`` returns the batch of step ``i``.
    Metrics are fetched from the device only at log steps (no per-step host sync). ``prefetch``: batches
    built ahead on a background thread (:class:`jaxgest.prefetch.Prefetcher`; 0 = none), the same batches.
    """
    from jaxgest.prefetch import Prefetcher

    from tqdm.auto import tqdm

    check_intervals(log_every=log_every, ckpt_every=ckpt_every)
    start = int(jax.device_get(state.step))
    if start >= num_steps:
        return state
    bar = tqdm(total=num_steps, initial=start, desc=desc, disable=not progress, dynamic_ncols=True, leave=False)
    last_log_time = time.perf_counter()
    metrics = {}
    next_batch = Prefetcher(batch_fn, stop=num_steps, depth=prefetch).get if prefetch else batch_fn
    for i in range(start, num_steps):
        batch = next_batch(i)
        state, metrics = step_fn(state, batch, key)
        step = i + 1
        at_log = step % log_every == 0 or step == num_steps
        at_ckpt = checkpointer is not None and (step % ckpt_every == 0 or step == num_steps)
        if at_log or at_ckpt:
            host = {k: float(np.asarray(jax.device_get(v))) for k, v in metrics.items()}
            _check_finite(step, host, desc, checkpointer)
            if at_log:
                now = time.perf_counter()
                host["steps_per_s"] = log_every / max(now - last_log_time, 1e-9) if step > start + 1 else 0.0
                last_log_time = now
                if logger is not None:
                    try:
                        logger.log(step, host)
                    except WriteError as e:
                        raise WriteError(f"{e}; stopped at step {step}, {_kept(checkpointer)}") from None
                if on_log is not None:
                    on_log(step, host)
                bar.set_postfix({k: f"{v:.4g}" for k, v in host.items() if k == "loss"})
            if at_ckpt:
                _check_params(step, state.params, desc, checkpointer)
                checkpointer.save(state)
        bar.update(1)
    bar.close()
    return state

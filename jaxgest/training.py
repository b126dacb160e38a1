"""Shared training machinery: TrainState, orbax checkpoints with a stored config, metrics.jsonl, the loop.

Every model (TGST autoencoder, TGST transformer, ZEGGS) trains through :func:`train_loop`:

* the step is ``(state, batch, key) -> (state, metrics)``, jit-compiled once with the state donated;
* the batch for step ``i`` is a pure function of ``(seed, i)`` (``batch_fn(i)``), so a run killed at any
  point and resumed from its last checkpoint ends with exactly the parameters of an uninterrupted run;
* orbax ``CheckpointManager`` keeps ``{params, opt_state, step}`` plus a JSON ``meta`` item holding the
  kind of model, its config and the skeleton signature; restoring with a different one stops with a
  one-line :class:`~jaxgest.errors.CheckpointError` that names the differing fields;
* ``workdir/metrics.jsonl`` gets one JSON line per log step and ``workdir/config.json`` the config;
* a non-finite loss stops training with :class:`~jaxgest.errors.TrainingError`, keeping the last good
  checkpoint (nothing is saved after the bad step). Metrics are checked at every log or checkpoint step,
  and the parameters before every save (a NaN gradient with a still-finite loss is caught there), e.g.
  ``tgst autoencoder: non-finite loss at step 120; stopped, the last good checkpoint (step 100) is kept
  (lower the learning rate or check the data for NaN)``.

References: STYLE.md (big_vision train loop, flax examples' orbax usage).
"""

from __future__ import annotations

import json
import math
import pathlib
import time
from typing import Any, Callable, Iterable, Mapping, Optional

import jax
import numpy as np
from flax.training.train_state import TrainState  # noqa: F401  (re-exported: the state every step uses)

from jaxgest.errors import CheckpointError, TrainingError
from jaxgest.io import write_text_atomic

__all__ = [
    "TrainState",
    "Checkpointer",
    "MetricsLogger",
    "train_loop",
    "config_diff",
    "write_json_atomic",
]


def write_json_atomic(path, obj) -> None:
    """Write JSON to ``path`` through a temporary file and ``os.replace`` (never a half-written file)."""
    write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (tuple, set)):
        return list(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _normalise(obj):
    """JSON round trip so tuples/lists and numpy scalars compare equal to what was stored."""
    return json.loads(json.dumps(obj, sort_keys=True, default=_json_default))


def config_diff(stored: Mapping, requested: Mapping, prefix: str = "") -> list[str]:
    """Flattened ``key: stored -> requested`` descriptions of every differing field (sorted)."""
    out = []
    keys = sorted(set(stored) | set(requested))
    for k in keys:
        a, b = stored.get(k, "<absent>"), requested.get(k, "<absent>")
        name = f"{prefix}{k}"
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out.extend(config_diff(a, b, prefix=name + "."))
        elif a != b:
            out.append(f"{name}: {a!r} -> {b!r}")
    return out


class Checkpointer:
    """orbax ``CheckpointManager`` over ``workdir/checkpoints`` with a config/skeleton-checked meta item.

    Args:
      workdir: the run directory.
      kind: what is trained (``"tgst_autoencoder"``, ``"tgst_transformer"``, ``"zeggs"``); part of the check.
      config: JSON-serialisable model/training config; compared on restore.
      skeleton: optional skeleton signature string; compared on restore.
      subdir: checkpoint folder name inside the workdir (one per trained stage).
      max_to_keep: how many step checkpoints to keep.
      ignore: config keys not compared on restore (e.g. the requested number of steps).
    """

    def __init__(
        self,
        workdir,
        *,
        kind: str,
        config: Mapping,
        skeleton: Optional[str] = None,
        subdir: str = "checkpoints",
        max_to_keep: int = 2,
        ignore: Iterable[str] = ("steps",),
        read_only: bool = False,
    ):
        import orbax.checkpoint as ocp

        self._ocp = ocp
        self.workdir = pathlib.Path(workdir)
        self.directory = (self.workdir / subdir).resolve()
        self.kind = kind
        self.ignore = tuple(ignore)
        self.meta = _normalise({"kind": kind, "config": dict(config), "skeleton": skeleton})
        if read_only:  # orbax logs three warnings about read-only options it adjusts; they are expected
            import logging

            logging.getLogger("absl").setLevel(logging.ERROR)
        if read_only and not self.directory.is_dir():
            raise CheckpointError(f"{self.workdir}: no checkpoint found (missing {self.directory.name}/)")
        if not read_only:
            self.directory.mkdir(parents=True, exist_ok=True)
        options = ocp.CheckpointManagerOptions(
            max_to_keep=max_to_keep,
            create=not read_only,
            enable_async_checkpointing=False,
            cleanup_tmp_directories=not read_only,
            read_only=read_only,
        )
        self.manager = ocp.CheckpointManager(self.directory, options=options, item_names=("state", "meta"))

    # -- queries -----------------------------------------------------------------------------------------
    def latest_step(self) -> Optional[int]:
        return self.manager.latest_step()

    def stored_meta(self, step: Optional[int] = None) -> Optional[dict]:
        step = self.latest_step() if step is None else step
        if step is None:
            return None
        restored = self.manager.restore(step, args=self._ocp.args.Composite(meta=self._ocp.args.JsonRestore()))
        return dict(restored["meta"])

    def check_meta(self, stored: Mapping) -> None:
        """Raise :class:`CheckpointError` naming what differs between the stored and requested meta."""
        problems = []
        if stored.get("kind") != self.meta["kind"]:
            problems.append(f"model kind: {stored.get('kind')!r} -> {self.meta['kind']!r}")
        if stored.get("skeleton") != self.meta["skeleton"] and self.meta["skeleton"] is not None:
            problems.append(f"skeleton signature: {stored.get('skeleton')} -> {self.meta['skeleton']}")
        a = {k: v for k, v in (stored.get("config") or {}).items() if k not in self.ignore}
        b = {k: v for k, v in self.meta["config"].items() if k not in self.ignore}
        problems.extend(config_diff(a, b))
        if problems:
            shown = "; ".join(problems[:4]) + (f"; and {len(problems) - 4} more" if len(problems) > 4 else "")
            raise CheckpointError(
                f"{self.directory}: checkpoint does not match the requested model ({shown}); "
                "use another --workdir or the same preset"
            )

    # -- save / restore ----------------------------------------------------------------------------------
    def save(self, state, *, force: bool = False) -> None:
        """Save ``{params, opt_state, step}`` and the meta item at ``state.step``."""
        step = int(jax.device_get(state.step))
        payload = {"params": state.params, "opt_state": state.opt_state, "step": state.step}
        self.manager.save(
            step,
            args=self._ocp.args.Composite(
                state=self._ocp.args.StandardSave(payload), meta=self._ocp.args.JsonSave(self.meta)
            ),
            force=force,
        )
        self.manager.wait_until_finished()

    def restore(self, state, step: Optional[int] = None):
        """Restore into the structure of ``state`` (shapes/dtypes/shardings taken from it).

        Returns ``state`` unchanged when the workdir holds no checkpoint yet.
        """
        step = self.latest_step() if step is None else step
        if step is None:
            return state
        self.check_meta(self.stored_meta(step))
        target = {"params": state.params, "opt_state": state.opt_state, "step": state.step}
        abstract = jax.tree_util.tree_map(_abstract_like, target)
        try:
            restored = self.manager.restore(
                step, args=self._ocp.args.Composite(state=self._ocp.args.StandardRestore(abstract))
            )["state"]
        except (ValueError, KeyError, TypeError) as e:  # structure/shape mismatch
            raise CheckpointError(
                f"{self.directory}: checkpoint at step {step} does not fit this model "
                f"({type(e).__name__}: {str(e).splitlines()[0][:200]})"
            ) from None
        return state.replace(params=restored["params"], opt_state=restored["opt_state"], step=restored["step"])

    def restore_params(self, params_template, step: Optional[int] = None):
        """Restore only the parameters (inference); raises CheckpointError when there is no checkpoint."""
        step = self.latest_step() if step is None else step
        if step is None:
            raise CheckpointError(f"{self.workdir}: no checkpoint found in {self.directory.name}/")
        self.check_meta(self.stored_meta(step))
        restored = self.manager.restore(step, args=self._ocp.args.Composite(state=self._ocp.args.StandardRestore()))
        params = restored["state"]["params"]
        want = jax.tree_util.tree_structure(params_template)
        got = jax.tree_util.tree_structure(params)
        if want != got:
            raise CheckpointError(f"{self.directory}: checkpoint parameters do not fit this model")
        return jax.tree_util.tree_map(lambda t, x: np.asarray(x).astype(t.dtype), params_template, params)

    def close(self) -> None:
        # orbax starts a thread at construction that removes unfinished temporary checkpoints of earlier runs;
        # wait for it too, or a process that exits right away (nothing to train) logs a RuntimeError from it.
        getattr(self.manager, "_maybe_await_cleanup_tmp_directory", lambda: None)()
        self.manager.wait_until_finished()
        self.manager.close()


def _abstract_like(x):
    x = jax.numpy.asarray(x) if not hasattr(x, "shape") else x
    sharding = getattr(x, "sharding", None)
    return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding)


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
        with open(self.path, "a") as f:
            f.write(json.dumps(record, sort_keys=True) + "\n")
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


@jax.jit
def _all_finite(tree) -> jax.Array:
    leaves = [jax.numpy.all(jax.numpy.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)
              if jax.numpy.issubdtype(x.dtype, jax.numpy.inexact)]
    return jax.numpy.all(jax.numpy.stack(leaves)) if leaves else jax.numpy.bool_(True)


def _check_params(step: int, params, stage: str, checkpointer) -> None:
    """Before a save: the loss of a step is computed before its update, so a NaN/inf gradient with a finite
    loss would otherwise be checkpointed."""
    if not bool(jax.device_get(_all_finite(params))):
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
):
    """Run ``step_fn`` from ``state.step`` up to ``num_steps`` (resumes from a restored state).

    ``step_fn(state, batch, key) -> (state, metrics)`` is expected to be jit-compiled with the state
    donated and to ``fold_in(key, state.step)`` inside; ``batch_fn(i)`` returns the batch of step ``i``.
    Metrics are fetched from the device only at log steps (no per-step host sync).
    """
    from tqdm.auto import tqdm

    check_intervals(log_every=log_every, ckpt_every=ckpt_every)
    start = int(jax.device_get(state.step))
    if start >= num_steps:
        return state
    bar = tqdm(total=num_steps, initial=start, desc=desc, disable=not progress, dynamic_ncols=True, leave=False)
    last_log_time = time.perf_counter()
    metrics = {}
    for i in range(start, num_steps):
        batch = batch_fn(i)
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
                    logger.log(step, host)
                if on_log is not None:
                    on_log(step, host)
                bar.set_postfix({k: f"{v:.4g}" for k, v in host.items() if k == "loss"})
            if at_ckpt:
                _check_params(step, state.params, desc, checkpointer)
                checkpointer.save(state)
        bar.update(1)
    bar.close()
    return state

"""Shared training machinery: TrainState, orbax checkpoints with a stored config, metrics.jsonl, the loop.

Every model (TGST autoencoder, TGST transformer, ZEGGS) trains through :func:`train_loop`:

* the step is ``(state, batch, key) -> (state, metrics)``, jit-compiled once with the state donated;
* the batch for step ``i`` is a pure function of ``(seed, i)`` (``batch_fn(i)``), so a run killed at any
  point and resumed from its last checkpoint ends with exactly the parameters of an uninterrupted run;
* orbax ``CheckpointManager`` keeps ``{params, opt_state, step}`` plus a JSON ``meta`` item holding the
  kind of model, its config and the skeleton signature; restoring with a different one stops with a
  one-line :class:`~jaxgest.errors.CheckpointError` that names the differing fields;
* faults of the environment are one line: a checkpoint that cannot be read (truncated, corrupted -- each
  stores a sha256 of its arrays -- or missing files) is skipped for the newest readable one with a one-line
  warning (``strict_checkpoints`` / ``--strict``: an error instead), a save that cannot complete (disk full,
  read-only) is a :class:`~jaxgest.errors.WriteError` with no partial folder left, and a workdir or
  checkpoint stamped with a newer ``format_version`` (:data:`FORMAT_VERSION`; absent = 1) or naming an
  unknown model is refused (:func:`check_workdir_config`);
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
import contextvars
import json
import logging
import math
import os
import pathlib
import sys
import time
from typing import Any, Callable, Iterable, Mapping, Optional

import jax
import numpy as np
from flax.training.train_state import TrainState  # noqa: F401  (re-exported: the state every step uses)

from jaxgest.errors import CheckpointError, TrainingError, WriteError
from jaxgest.io import write_error, write_text_atomic

__all__ = [
    "TrainState",
    "make_update_step",
    "Checkpointer",
    "MetricsLogger",
    "train_loop",
    "config_diff",
    "write_json_atomic",
    "FORMAT_VERSION",
    "check_workdir_config",
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


FORMAT_VERSION = 1
MODELS = ("tgst", "zeggs")  # what config.json's "kind" (TGST) / "model" (ZeroEGGS) may name
"""Workdir format written by this version (``"format_version"`` in config.json and in each checkpoint's meta;
absent = 1). A workdir stamped with a newer version is refused with a one-line error."""

_STRICT = contextvars.ContextVar("jaxgest_strict_checkpoints", default=False)


@contextlib.contextmanager
def strict_checkpoints(strict: bool = True):
    """Within this context an unreadable checkpoint is an error instead of a fall-back to an older one
    (what ``--strict`` sets for a command)."""
    token = _STRICT.set(bool(strict))
    try:
        yield
    finally:
        _STRICT.reset(token)


def warn(message: str) -> None:
    """One ``jaxgest: warning: ...`` line on stderr (a fault that was handled; the command goes on)."""
    print(f"jaxgest: warning: {message}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def _quiet_absl(level=logging.CRITICAL):
    """orbax logs through absl (read-only option adjustments, missing optional metadata files, and the errors
    it then raises); those are expected or reported by us in one line, so they are not shown."""
    logger = logging.getLogger("absl")
    old = logger.level
    logger.setLevel(max(level, old))
    try:
        yield
    finally:
        logger.setLevel(old)


def _mute_closed_loop_errors() -> None:
    """When orbax gives up on a damaged checkpoint (or a failed save), tensorstore still completes the
    outstanding reads/writes and their callbacks hit orbax's already closed asyncio loop: each prints a
    "RuntimeError: Event loop is closed" traceback through ``sys.unraisablehook`` (while orbax gives up, or
    later, often at exit). Installed by every Checkpointer, this hook drops those, and only those; every
    other unraisable error goes through to the previous hook."""
    if getattr(sys.unraisablehook, "_jaxgest_mutes_closed_loop", False):
        return
    previous = sys.unraisablehook

    def hook(unraisable):
        exc = unraisable.exc_value
        if isinstance(exc, RuntimeError) and str(exc) == "Event loop is closed":
            return
        previous(unraisable)

    hook._jaxgest_mutes_closed_loop = True
    sys.unraisablehook = hook


class _Unreadable(Exception):
    """A checkpoint step that cannot be read (truncated/corrupted/missing files): ``reason`` says how."""


def _reason(e: BaseException) -> str:
    """A short description of why orbax/tensorstore could not read a checkpoint."""
    if isinstance(e, _Unreadable):
        return str(e)
    texts, seen, x = [], set(), e
    while x is not None and id(x) not in seen:  # the whole cause chain: orbax wraps tensorstore's error
        seen.add(id(x))
        texts.append((str(x).strip().splitlines() or [""])[0])
        x = x.__cause__ or x.__context__
    chain = " | ".join(texts)
    if isinstance(e, json.JSONDecodeError) or "JSONDecodeError" in chain or "Expecting " in chain:
        return "its metadata is not valid JSON"
    if any(m in chain for m in ("OUT_OF_RANGE", "byte range", "DATA_LOSS", "Error decoding", "corrupt")):
        return "a data file is truncated or corrupted"
    missing = ("NOT_FOUND", "No such file", "does not exist", "not found", "Not found")
    if isinstance(e, FileNotFoundError) or any(m in chain for m in missing):
        return "a file is missing"
    if "Encountered error while reading" in chain:
        return "a data file is missing or corrupted"
    text = texts[0]
    short = text if len(text) <= 100 else text[:97] + "..."
    return f"{type(e).__name__}: {short}" if short else type(e).__name__


def _digest(tree) -> Optional[str]:
    """sha256 of a pytree's arrays (names, shapes, dtypes, bytes; order-independent of the container types),
    saved in a checkpoint's meta and verified on restore: a flipped byte that still decodes is caught too.
    None when an array is not addressable from this process (multi-host sharded state: not checked)."""
    import hashlib

    h = hashlib.sha256()
    try:
        leaves = sorted((_path_names(p), x) for p, x in jax.tree_util.tree_flatten_with_path(tree)[0])
        for name, x in leaves:
            a = np.ascontiguousarray(np.asarray(jax.device_get(x)))
            h.update(repr((name, a.shape, a.dtype.str)).encode())
            h.update(a.tobytes())
    except Exception:  # noqa: BLE001  (not fully addressable)
        return None
    return h.hexdigest()


def _flat(d: Mapping, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, Mapping):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _path_names(path) -> tuple:
    """A pytree key path as plain names, so optax namedtuples (attributes) compare equal to orbax's stored
    dict/list metadata."""
    out = []
    for k in path:
        for attr in ("key", "idx", "name"):
            if hasattr(k, attr):
                out.append(str(getattr(k, attr)))
                break
        else:
            out.append(str(k))
    return tuple(out)


def _shapes(tree) -> dict:
    return {_path_names(p): tuple(x.shape) for p, x in jax.tree_util.tree_flatten_with_path(tree)[0]}


class Checkpointer:
    """orbax ``CheckpointManager`` over ``workdir/checkpoints`` with a config/skeleton-checked meta item.

    Restoring takes the newest *readable* checkpoint: a step whose files are truncated, corrupted or missing
    is reported in one warning line naming the workdir, the stage and the step, and the previous one is used
    (:func:`strict_checkpoints` / ``--strict``: a one-line :class:`CheckpointError` instead). Nothing is
    deleted: a training run (not read-only) that falls back moves the unreadable step folder aside to
    ``<subdir>.unreadable-step-<N>`` so that step can be trained and saved again. A save that cannot complete
    (full disk, read-only folder) is a one-line :class:`CheckpointError`; its partial temporary folder is
    removed and the earlier checkpoints are untouched.

    Args:
      workdir: the run directory.
      kind: what is trained (``"tgst_autoencoder"``, ``"tgst_transformer"``, ``"zeggs"``); part of the check.
      config: JSON-serialisable model/training config; compared on restore.
      skeleton: optional skeleton signature string; compared on restore.
      subdir: checkpoint folder name inside the workdir (one per trained stage).
      max_to_keep: how many step checkpoints to keep (at least two, so there is one to fall back to).
      ignore: config keys not compared on restore (e.g. the requested number of steps).
      read_only: open for inference (nothing is created, moved or cleaned up).
      strict: refuse to fall back past an unreadable checkpoint (default: :func:`strict_checkpoints`).
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
        strict: Optional[bool] = None,
    ):
        import orbax.checkpoint as ocp

        self._ocp = ocp
        self.workdir = pathlib.Path(workdir)
        self.directory = (self.workdir / subdir).resolve()
        self.kind = kind
        self.stage = pathlib.PurePath(subdir).name if subdir != "checkpoints" else kind
        self.ignore = tuple(ignore)
        self.read_only = read_only
        self.strict = strict
        self.restored_step: Optional[int] = None  # the step the last restore used
        self.meta = _normalise({"kind": kind, "config": dict(config), "skeleton": skeleton})
        check_workdir_config(self.workdir, kind, lenient=True)
        _mute_closed_loop_errors()  # before any read: a damaged file's callbacks fire while orbax gives up
        if read_only and not self.directory.is_dir():
            raise CheckpointError(f"{self.workdir}: no checkpoint found (missing {self.directory.name}/)")
        if not read_only:
            try:
                self.directory.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise CheckpointError(f"{self.directory}: cannot create the checkpoint folder "
                                      f"({e.strerror or e})") from None
        with _quiet_absl(logging.ERROR):  # read-only: expected warnings about the options orbax adjusts
            options = ocp.CheckpointManagerOptions(
                max_to_keep=max(int(max_to_keep), 1),
                create=not read_only,
                enable_async_checkpointing=False,
                cleanup_tmp_directories=not read_only,
                read_only=read_only,
            )
            self.manager = ocp.CheckpointManager(self.directory, options=options,
                                                 item_names=("state", "meta"))

    def _strict(self) -> bool:
        return _STRICT.get() if self.strict is None else bool(self.strict)

    def _where(self, step) -> str:
        return f"{self.workdir}: {self.stage} checkpoint at step {step}"

    # -- queries -----------------------------------------------------------------------------------------
    def latest_step(self) -> Optional[int]:
        return self.manager.latest_step()

    def all_steps(self) -> list[int]:
        return sorted(int(s) for s in self.manager.all_steps())

    def _read_meta(self, step: int) -> dict:
        try:
            with _quiet_absl():
                restored = self.manager.restore(
                    step, args=self._ocp.args.Composite(meta=self._ocp.args.JsonRestore()))
            meta = restored["meta"]
            if not isinstance(meta, Mapping):
                raise _Unreadable("its meta item is not a JSON object")
        except MemoryError:
            raise
        except Exception as e:  # noqa: BLE001  (orbax/tensorstore raise many types for a damaged file)
            _mute_closed_loop_errors()
            raise _Unreadable(_reason(e)) from None
        return dict(meta)

    def stored_meta(self, step: Optional[int] = None) -> Optional[dict]:
        """The meta item of ``step`` (default: the newest checkpoint whose meta is readable; None if none)."""
        if step is not None:
            try:
                return self._read_meta(step)
            except _Unreadable as e:
                raise CheckpointError(f"{self._where(step)} is unreadable ({e})") from None
        for s in reversed(self.all_steps()):
            try:
                return self._read_meta(s)
            except _Unreadable:
                continue
        return None

    def check_meta(self, stored: Optional[Mapping]) -> None:
        """Raise :class:`CheckpointError` naming what differs between the stored and requested meta."""
        if stored is None:
            return
        version = stored.get("format_version", 1)
        if not isinstance(version, int) or version > FORMAT_VERSION:
            raise CheckpointError(
                f"{self.directory}: checkpoint written by a newer jaxgest (format version {version}; this "
                f"one reads up to {FORMAT_VERSION}); upgrade jaxgest, or retrain into a new --workdir")
        problems = []
        if stored.get("kind") != self.meta["kind"]:
            problems.append(f"model kind: {stored.get('kind')!r} -> {self.meta['kind']!r}")
        if stored.get("skeleton") != self.meta["skeleton"] and self.meta["skeleton"] is not None:
            problems.append(f"skeleton signature: {stored.get('skeleton')} -> {self.meta['skeleton']}")
        a = {k: v for k, v in (stored.get("config") or {}).items() if k not in self.ignore}
        b = {k: v for k, v in self.meta["config"].items() if k not in self.ignore}
        diff = config_diff(a, b)
        fa, fb = _flat(a), _flat(b)
        missing, extra = sorted(set(fb) - set(fa)), sorted(set(fa) - set(fb))
        changed = [k for k in set(fa) & set(fb) if fa[k] != fb[k]]
        if not problems and not changed and (missing or extra):
            # only fields added or removed between versions of jaxgest: another layout, not another preset
            what = "; ".join(x for x in (
                f"without {', '.join(missing[:4])}" if missing else "",
                f"with unknown {', '.join(extra[:4])}" if extra else "") if x)
            older = "an older" if not extra else ("a newer" if not missing else "another")
            raise CheckpointError(
                f"{self.directory}: checkpoint from {older} version of jaxgest (config {what}); retrain "
                "into a new --workdir with this version (checkpoints are not converted)")
        problems.extend(diff)
        if problems:
            shown = "; ".join(problems[:4]) + (f"; and {len(problems) - 4} more" if len(problems) > 4 else "")
            raise CheckpointError(
                f"{self.directory}: checkpoint does not match the requested model ({shown}); "
                "use another --workdir or the same preset"
            )

    # -- save / restore ----------------------------------------------------------------------------------
    def save(self, state, *, force: bool = False) -> None:
        """Save ``{params, opt_state, step}`` and the meta item at ``state.step``.

        A save that cannot complete (full disk, read-only folder, ...) raises a one-line
        :class:`CheckpointError`; its partial temporary folder is removed, earlier checkpoints stay.
        """
        step = int(jax.device_get(state.step))
        payload = {"params": state.params, "opt_state": state.opt_state, "step": state.step}
        before = set(self._tmp_folders())
        meta = {**self.meta, "format_version": FORMAT_VERSION}
        digest = _digest(payload)
        if digest is not None:
            meta["sha256"] = digest
        try:
            with _quiet_absl():
                self.manager.save(
                    step,
                    args=self._ocp.args.Composite(
                        state=self._ocp.args.StandardSave(payload), meta=self._ocp.args.JsonSave(meta)),
                    force=force,
                )
                self.manager.wait_until_finished()
        except MemoryError:
            raise
        except Exception as e:  # noqa: BLE001
            _mute_closed_loop_errors()
            self._settle()
            self._remove_partial(step, before)
            last = [s for s in self.all_steps() if s != step]
            kept = (f"the last good checkpoint (step {last[-1]}) is kept" if last else
                    "no checkpoint was written")
            raise WriteError(f"{self._where(step)} could not be written ({_write_reason(e)}); stopped, "
                                  f"{kept}") from None

    def _settle(self, timeout: float = 120.0) -> None:
        """After a failed save: let orbax's background writer threads of the other items end (quietly: they
        fail too, and would log tracebacks and asyncio 'Event loop is closed' errors) before cleaning up."""
        import threading

        try:
            from orbax.checkpoint._src.futures.future import _SignalingThread as orbax_thread
        except ImportError:  # another orbax layout: wait for every non-daemon helper thread instead
            orbax_thread = threading.Thread
        deadline = time.monotonic() + timeout
        with _quiet_absl():
            for t in threading.enumerate():
                if t is not threading.current_thread() and isinstance(t, orbax_thread) and t.is_alive():
                    t.join(max(deadline - time.monotonic(), 0.0))
            with contextlib.suppress(Exception):
                self.manager.wait_until_finished()

    def _tmp_folders(self) -> list:
        try:
            return [p for p in self.directory.iterdir() if "orbax-checkpoint-tmp" in p.name]
        except OSError:
            return []

    def _remove_partial(self, step: int, before) -> None:
        """Remove what a failed save of ``step`` left (its temporary folder; the step folder if it is new)."""
        import shutil

        for p in self._tmp_folders():
            if p not in before:
                shutil.rmtree(p, ignore_errors=True)
        final = self.directory / str(step)
        if final.is_dir() and not (final / "_CHECKPOINT_METADATA").is_file():
            shutil.rmtree(final, ignore_errors=True)
        try:
            with _quiet_absl():
                self.manager.reload()
        except Exception:  # noqa: BLE001
            pass

    def _candidates(self, step: Optional[int]) -> list[int]:
        steps = self.all_steps()
        if step is not None:
            return [int(step)]
        return list(reversed(steps))

    def _restore_newest(self, read: Callable[[int], Any], step: Optional[int]):
        """``(step, read(step))`` of the newest readable checkpoint; one warning line per fall-back."""
        bad: list[tuple[int, str]] = []
        for s in self._candidates(step):
            try:
                out = read(s)
            except _Unreadable as e:
                bad.append((s, str(e)))
                if self._strict() or step is not None:
                    older = [t for t in self.all_steps() if t < s]
                    hint = (f"; --strict: not falling back to step {older[-1]}" if older and step is None else
                            f"; restore {self.directory.name}/ from a backup or retrain into a new --workdir")
                    raise CheckpointError(f"{self._where(s)} is unreadable ({e}){hint}") from None
                continue
            if bad:
                self._report_fallback(bad, s)
            self.restored_step = s
            return s, out
        if bad:
            listed = "; ".join(f"step {s}: {r}" for s, r in bad)
            raise CheckpointError(f"{self.workdir}: no readable {self.stage} checkpoint ({listed}); restore "
                                  f"{self.directory.name}/ from a backup, or move it aside to train from "
                                  "scratch")
        return None, None

    def _report_fallback(self, bad, used: int) -> None:
        steps = ", ".join(str(s) for s, _ in bad)
        reasons = "; ".join(sorted({r for _, r in bad}))
        what = (f"{self.workdir}: {self.stage} checkpoint at step {steps} is unreadable ({reasons})"
                if len(bad) == 1 else
                f"{self.workdir}: {self.stage} checkpoints at steps {steps} are unreadable ({reasons})")
        if self.read_only:
            warn(f"{what}; using step {used} instead (nothing was changed; --strict refuses)")
            return
        moved = [self._set_aside(s) for s, _ in bad]
        with _quiet_absl():
            self.manager.reload()
        warn(f"{what}; resuming from step {used} (moved to {', '.join(moved)}; nothing was deleted)")

    def _set_aside(self, step: int) -> str:
        src = self.directory / str(step)
        dst = self.directory.with_name(f"{self.directory.name}.unreadable-step-{step}")
        k = 1
        while dst.exists():
            k += 1
            dst = self.directory.with_name(f"{self.directory.name}.unreadable-step-{step}.{k}")
        if jax.process_index() == 0:
            try:
                src.rename(dst)
            except OSError as e:
                raise CheckpointError(f"{self._where(step)} is unreadable and cannot be moved aside "
                                      f"({e.strerror or e}); move {src} away by hand") from None
        if jax.process_count() > 1:
            from jax.experimental import multihost_utils

            multihost_utils.sync_global_devices(f"jaxgest: unreadable {self.stage} step {step} set aside")
        try:
            return str(dst.relative_to(self.workdir.resolve()))
        except ValueError:
            return str(dst)

    def _read_state(self, step: int, abstract):
        """Restore ``{params, opt_state, step}`` of ``step`` (``abstract``: target structure, or None)."""
        meta = self._read_meta(step)
        self.check_meta(meta)
        args = (self._ocp.args.StandardRestore(abstract) if abstract is not None else
                self._ocp.args.StandardRestore())
        try:
            with _quiet_absl():
                restored = self.manager.restore(step, args=self._ocp.args.Composite(state=args))["state"]
        except MemoryError:
            raise
        except Exception as e:  # noqa: BLE001
            _mute_closed_loop_errors()
            if abstract is not None:
                mismatch = self._structure_mismatch(step, abstract)
                if mismatch:
                    raise CheckpointError(f"{self.directory}: checkpoint at step {step} does not fit this "
                                          f"model ({mismatch})") from None
            raise _Unreadable(_reason(e)) from None
        if meta.get("sha256") is not None and _digest(restored) not in (None, meta["sha256"]):
            raise _Unreadable("its arrays do not match the checksum saved with them")
        if not bool(jax.device_get(_all_finite(restored))):
            raise _Unreadable("it holds NaN/inf values, which training never saves")
        return restored

    def _structure_mismatch(self, step: int, abstract) -> Optional[str]:
        """How the stored tree differs from ``abstract`` (None: it does not, or its metadata is damaged)."""
        try:
            with _quiet_absl():
                md = self._ocp.StandardCheckpointer().metadata(self.directory / str(step) / "state")
            stored = _shapes(getattr(md, "item_metadata", md))
        except Exception:  # noqa: BLE001
            return None
        want = _shapes(abstract)
        if stored == want or not stored:  # nothing listed: the tree metadata itself is damaged
            return None
        missing = sorted(set(want) - set(stored))
        extra = sorted(set(stored) - set(want))
        shape = sorted(k for k in set(want) & set(stored) if want[k] != stored[k])
        parts = []
        if missing:
            parts.append(f"{len(missing)} missing, e.g. {'.'.join(missing[0])}")
        if extra:
            parts.append(f"{len(extra)} unexpected, e.g. {'.'.join(extra[0])}")
        if shape:
            k = shape[0]
            parts.append(f"{len(shape)} of another shape, e.g. {'.'.join(k)} {stored[k]} vs {want[k]}")
        return "arrays: " + "; ".join(parts)

    def restore(self, state, step: Optional[int] = None):
        """Restore into the structure of ``state`` (shapes/dtypes/shardings taken from it).

        Returns ``state`` unchanged when the workdir holds no checkpoint yet. Without ``step``, the newest
        readable checkpoint (see the class docstring).
        """
        target = {"params": state.params, "opt_state": state.opt_state, "step": state.step}
        abstract = jax.tree_util.tree_map(_abstract_like, target)
        s, restored = self._restore_newest(lambda t: self._read_state(t, abstract), step)
        if s is None:
            return state
        return state.replace(params=restored["params"], opt_state=restored["opt_state"], step=restored["step"])

    def restore_params(self, params_template, step: Optional[int] = None):
        """Restore only the parameters (inference); raises CheckpointError when there is no checkpoint."""
        s, restored = self._restore_newest(lambda t: self._read_state(t, None), step)
        if s is None:
            raise CheckpointError(f"{self.workdir}: no checkpoint found in {self.directory.name}/")
        params = restored["params"]
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


def _write_reason(e: BaseException) -> str:
    """Why a write failed, short: the OS error (e.g. 'No space left on device') when there is one."""
    first, seen = e, set()
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if isinstance(e, OSError) and e.strerror:
            return e.strerror
        text = str(e)
        for marker, say in (("No space left", "No space left on device"), ("Read-only file system",
                            "Read-only file system"), ("Permission denied", "Permission denied")):
            if marker in text:
                return say
        e = e.__cause__ or e.__context__
    return _reason(first)


def check_workdir_config(workdir, kind: Optional[str] = None, *, lenient: bool = False) -> Optional[dict]:
    """The workdir's config.json as a dict (None when there is none), after the format checks.

    One-line :class:`CheckpointError` when it is not valid JSON (``lenient``: None instead -- a checkpointer
    leaves that to the loader, and training rewrites the file), when it carries a ``format_version`` newer
    than :data:`FORMAT_VERSION` (absent = 1), when it names no model this version knows, or another model
    than ``kind`` (``"tgst_autoencoder"`` -> ``tgst``; kinds outside :data:`MODELS` are not checked).
    """
    workdir = pathlib.Path(workdir)
    path = workdir / "config.json"
    if not path.is_file():
        return None
    try:
        stored = json.loads(path.read_text())
        if not isinstance(stored, dict):
            raise ValueError("not a JSON object")
    except (OSError, UnicodeDecodeError, ValueError) as e:
        why = (e.strerror if isinstance(e, OSError) and e.strerror else
               "not valid JSON: truncated or corrupted?")
        if lenient:
            return None
        raise CheckpointError(f"{path}: unreadable ({why}); restore it from a backup or retrain into a new "
                              "--workdir") from None
    version = stored.get("format_version", 1)
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise CheckpointError(f"{path}: format_version {version!r} is not a version number; retrain into a "
                              "new --workdir")
    if version > FORMAT_VERSION:
        raise CheckpointError(f"{workdir}: written by a newer jaxgest (workdir format {version}, this "
                              f"version reads up to {FORMAT_VERSION}); upgrade jaxgest, or retrain into a new "
                              "--workdir")
    model = stored.get("kind", stored.get("model"))
    if model not in MODELS:
        raise CheckpointError(f"{workdir}: config.json names {'no model' if model is None else repr(model)} "
                              f"(this jaxgest knows {', '.join(MODELS)}): an older layout or not a jaxgest "
                              "workdir; retrain into a new --workdir")
    family = (kind or "").split("_")[0]
    if family in MODELS and model != family:
        raise CheckpointError(f"{workdir}: a {model} workdir, not a {family} one; use another --workdir")
    return stored


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

"""orbax checkpoints of one trained stage, with a stored and checked meta item.

:class:`Checkpointer` wraps an orbax ``CheckpointManager`` over ``workdir/<subdir>`` keeping
``{params, opt_state, step}`` plus a JSON ``meta`` item holding the kind of model, its config and the
skeleton signature; restoring with a different one stops with a one-line
:class:`~jaxgest.runtime.errors.CheckpointError` that names the differing fields. Faults of the environment are one
line: a checkpoint that cannot be read (truncated, corrupted -- each stores a sha256 of its arrays -- or
missing files) is skipped for the newest readable one with a one-line warning (:func:`strict_checkpoints` /
``--strict``: an error instead), a save that cannot complete (disk full, read-only) is a
:class:`~jaxgest.runtime.errors.WriteError` with no partial folder left, and a workdir or checkpoint stamped with a
newer ``format_version`` or naming an unknown model is refused (:mod:`jaxgest.runtime.workdir_format`).

No process-wide side effects: absl logging is quietened only around the orbax calls that log expected
noise (:func:`jaxgest.runtime.orbax_noise.quiet_absl`), orbax's asyncio loops let their pending reads end before they
close only around those calls (:func:`jaxgest.runtime.orbax_noise.settled_event_loops`: a failed restore leaves no
coroutine behind to print tracebacks when it is collected), and the filter of asyncio's "Event loop is closed" errors
(:func:`jaxgest.runtime.orbax_noise.closed_loop_errors_muted`) is installed while a Checkpointer is open and removed by
:meth:`Checkpointer.close` (the command line installs it for the whole command, see :mod:`jaxgest.cli`).

The one-line reasons and the content digest are in :mod:`jaxgest.runtime.checkpoint_faults`.

References: flax examples' orbax usage.
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
import pathlib
import sys
import time
from typing import Any, Callable, Iterable, Mapping, Optional

import jax
import numpy as np

from jaxgest.runtime.checkpoint_faults import Unreadable, digest, flat, read_reason, tree_shapes, write_reason
from jaxgest.runtime.errors import CheckpointError, WriteError
from jaxgest.runtime.orbax_noise import closed_loop_errors_muted, quiet_absl, settled_event_loops
from jaxgest.runtime.workdir_format import FORMAT_VERSION, check_workdir_config, config_diff, normalise

__all__ = [
    "Checkpointer",
    "all_finite",
    "strict_checkpoints",
    "warn",
]

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


@contextlib.contextmanager
def _orbax_call(level=logging.CRITICAL):
    """Around every orbax call: its expected absl messages quietened, and its asyncio loops settled before they
    close (:func:`jaxgest.runtime.orbax_noise.settled_event_loops`: a failed read leaves no pending coroutine whose
    later collection would print tracebacks)."""
    with quiet_absl(level), settled_event_loops():
        yield


def warn(message: str) -> None:
    """One ``jaxgest: warning: ...`` line on stderr (a fault that was handled; the command goes on)."""
    print(f"jaxgest: warning: {message}", file=sys.stderr, flush=True)


class _Vanished(Exception):
    """A checkpoint step removed (by a concurrent training) while it was being read."""


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
      read_config: maps a stored config (of an older layout) to the current one before it is compared.
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
        read_config: Optional[Callable[[Mapping], Mapping]] = None,
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
        self.read_config = read_config
        self.read_only = read_only
        self.strict = strict
        self.restored_step: Optional[int] = None  # the step the last restore used
        self.meta = normalise({"kind": kind, "config": dict(config), "skeleton": skeleton})
        check_workdir_config(self.workdir, kind, lenient=True)
        if read_only and not self.directory.is_dir():
            raise CheckpointError(f"{self.workdir}: no checkpoint found (missing {self.directory.name}/)")
        if not read_only:
            try:
                self.directory.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise CheckpointError(f"{self.directory}: cannot create the checkpoint folder "
                                      f"({e.strerror or e})") from None
        # before any read (a damaged file's callbacks fire while orbax gives up); removed by close()
        self._muted = contextlib.ExitStack()
        self._muted.enter_context(closed_loop_errors_muted())
        try:
            with _orbax_call(logging.ERROR):  # read-only: expected warnings about the options orbax adjusts
                options = ocp.CheckpointManagerOptions(
                    max_to_keep=max(int(max_to_keep), 1),
                    create=not read_only,
                    enable_async_checkpointing=False,
                    cleanup_tmp_directories=not read_only,
                    read_only=read_only,
                )
                self.manager = ocp.CheckpointManager(self.directory, options=options,
                                                     item_names=("state", "meta"))
        except BaseException:
            self._muted.close()
            raise

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
            with _orbax_call():
                restored = self.manager.restore(
                    step, args=self._ocp.args.Composite(meta=self._ocp.args.JsonRestore()))
            meta = restored["meta"]
            if not isinstance(meta, Mapping):
                raise Unreadable("its meta item is not a JSON object")
        except MemoryError:
            raise
        except Exception as e:  # noqa: BLE001  (orbax/tensorstore raise many types for a damaged file)
            raise Unreadable(read_reason(e)) from None
        return dict(meta)

    def stored_meta(self, step: Optional[int] = None) -> Optional[dict]:
        """The meta item of ``step`` (default: the newest checkpoint whose meta is readable; None if none)."""
        if step is not None:
            try:
                return self._read_meta(step)
            except Unreadable as e:
                raise CheckpointError(f"{self._where(step)} is unreadable ({e})") from None
        for s in reversed(self.all_steps()):
            try:
                return self._read_meta(s)
            except Unreadable:
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
        stored_config = stored.get("config") or {}
        if self.read_config is not None:
            stored_config = normalise(dict(self.read_config(stored_config)))
        a = {k: v for k, v in stored_config.items() if k not in self.ignore}
        b = {k: v for k, v in self.meta["config"].items() if k not in self.ignore}
        diff = config_diff(a, b)
        fa, fb = flat(a), flat(b)
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
        checksum = digest(payload)
        if checksum is not None:
            meta["sha256"] = checksum
        try:
            with _orbax_call():
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
            self._settle()
            self._remove_partial(step, before)
            last = [s for s in self.all_steps() if s != step]
            kept = (f"the last good checkpoint (step {last[-1]}) is kept" if last else
                    "no checkpoint was written")
            raise WriteError(f"{self._where(step)} could not be written ({write_reason(e)}); stopped, "
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
        with _orbax_call():
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
            with _orbax_call():
                self.manager.reload()
        except Exception:  # noqa: BLE001
            pass

    def _candidates(self, step: Optional[int]) -> list[int]:
        steps = self.all_steps()
        if step is not None:
            return [int(step)]
        return list(reversed(steps))

    def _restore_newest(self, read: Callable[[int], Any], step: Optional[int]):
        """``(step, read(step))`` of the newest readable checkpoint; one warning line per fall-back.

        A reader (read-only) runs while a training may write: a step the writer removed meanwhile (an old
        one beyond ``max_to_keep``) is not a damaged checkpoint; the steps are listed again (a few times)."""
        for _ in range(5):
            try:
                return self._restore_newest_once(read, step)
            except _Vanished as e:
                vanished = e.args[0]
                with _orbax_call():
                    self.manager.reload()
        raise CheckpointError(f"{self._where(vanished)} was removed while it was read (a training writing to "
                              "this workdir replaces its checkpoints faster than they are read); try again")

    def _restore_newest_once(self, read: Callable[[int], Any], step: Optional[int]):
        bad: list[tuple[int, str]] = []
        for s in self._candidates(step):
            try:
                out = read(s)
            except Unreadable as e:
                if self.read_only and step is None and not (self.directory / str(s)).exists():
                    raise _Vanished(s) from None
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
        with _orbax_call():
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
            with _orbax_call():
                restored = self.manager.restore(step, args=self._ocp.args.Composite(state=args))["state"]
        except MemoryError:
            raise
        except Exception as e:  # noqa: BLE001
            if abstract is not None:
                mismatch = self._structure_mismatch(step, abstract)
                if mismatch:
                    raise CheckpointError(f"{self.directory}: checkpoint at step {step} does not fit this "
                                          f"model ({mismatch})") from None
            raise Unreadable(read_reason(e)) from None
        if meta.get("sha256") is not None and digest(restored) not in (None, meta["sha256"]):
            raise Unreadable("its arrays do not match the checksum saved with them")
        if not bool(jax.device_get(all_finite(restored))):
            raise Unreadable("it holds NaN/inf values, which training never saves")
        return restored

    def _structure_mismatch(self, step: int, abstract) -> Optional[str]:
        """How the stored tree differs from ``abstract`` (None: it does not, or its metadata is damaged)."""
        try:
            with _orbax_call():
                md = self._ocp.StandardCheckpointer().metadata(self.directory / str(step) / "state")
            stored = tree_shapes(getattr(md, "item_metadata", md))
        except Exception:  # noqa: BLE001
            return None
        want = tree_shapes(abstract)
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

    def __enter__(self) -> "Checkpointer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        # orbax starts a thread at construction that removes unfinished temporary checkpoints of earlier runs;
        # wait for it too, or a process that exits right away (nothing to train) logs a RuntimeError from it.
        try:
            getattr(self.manager, "_maybe_await_cleanup_tmp_directory", lambda: None)()
            self.manager.wait_until_finished()
            self.manager.close()
        finally:
            self._muted.close()


def _abstract_like(x):
    x = jax.numpy.asarray(x) if not hasattr(x, "shape") else x
    sharding = getattr(x, "sharding", None)
    return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding)


@jax.jit
def all_finite(tree) -> jax.Array:
    """Whether every inexact leaf of ``tree`` is finite (a scalar bool array)."""
    leaves = [jax.numpy.all(jax.numpy.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)
              if jax.numpy.issubdtype(x.dtype, jax.numpy.inexact)]
    return jax.numpy.all(jax.numpy.stack(leaves)) if leaves else jax.numpy.bool_(True)

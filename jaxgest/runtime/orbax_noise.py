"""Expected noise of orbax / tensorstore, silenced only where it is expected.

* :func:`quiet_absl`: absl logging raised to CRITICAL around orbax calls that log expected messages;
* :func:`closed_loop_errors_muted`: drops the "RuntimeError: Event loop is closed" unraisable errors that
  tensorstore callbacks raise after orbax gives up on a damaged checkpoint, and asyncio's "Task exception was
  never retrieved" log records of the tensorstore reads orbax abandoned (reentrant, restores the previous
  ``sys.unraisablehook`` and removes its logging filter); :func:`mute_closed_loop_errors_for_process` for an
  entry point;
* :func:`settled_event_loops`: the source of that noise removed. orbax runs each restore/save in a fresh
  asyncio loop and closes it as soon as the outer coroutine ends; when one array read fails, the reads of the
  other arrays are still pending, and whenever the garbage collector later finalises them each prints a
  traceback ("Exception ignored in: <coroutine object _read_array_index_and_device_put ...>", "Task was
  destroyed but it is pending!", "Task exception was never retrieved", "Event loop is closed"), or not,
  depending on its timing. Within this context a loop, before it closes, waits for its pending tasks to end and
  retrieves their exceptions (what ``asyncio.run`` does at its end), so nothing is left to be collected.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import sys
import threading

__all__ = ["quiet_absl", "closed_loop_errors_muted", "mute_closed_loop_errors_for_process", "settled_event_loops"]


@contextlib.contextmanager
def quiet_absl(level=logging.CRITICAL):
    """orbax logs through absl (read-only option adjustments, missing optional metadata files, and the errors
    it then raises); those are expected or reported by us in one line, so they are not shown."""
    logger = logging.getLogger("absl")
    old = logger.level
    logger.setLevel(max(level, old))
    try:
        yield
    finally:
        logger.setLevel(old)


_MUTE_LOCK = threading.Lock()
_MUTE_DEPTH = 0  # how many closed_loop_errors_muted() contexts are open
_MUTE_PREVIOUS = None  # the hook that was installed before the first of them


def _closed_loop_hook(unraisable):
    exc = unraisable.exc_value
    if isinstance(exc, RuntimeError) and str(exc) == "Event loop is closed":
        return
    (_MUTE_PREVIOUS or sys.__unraisablehook__)(unraisable)


_ORPHAN_MESSAGES = ("Task exception was never retrieved", "Future exception was never retrieved")


def _is_orbax_noise(exc: BaseException | None) -> bool:
    """An exception of an abandoned tensorstore read/write or of orbax's closed loop (and nothing else)."""
    if exc is None:
        return False
    if isinstance(exc, RuntimeError) and str(exc) == "Event loop is closed":
        return True
    return "tensorstore" in type(exc).__module__ or "tensorstore_spec" in str(exc)


class _OrphanTaskFilter(logging.Filter):
    """Drops asyncio's "Task exception was never retrieved" records whose exception is :func:`_is_orbax_noise`:
    when orbax gives up on a damaged checkpoint, the reads of its other arrays fail later, unobserved, and
    asyncio logs each one (with a traceback) when the task is garbage-collected, at any later moment."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not str(record.msg).startswith(_ORPHAN_MESSAGES):
            return True
        exc = record.exc_info[1] if record.exc_info else None
        return not _is_orbax_noise(exc)


_ORPHAN_FILTER = _OrphanTaskFilter()


def _mute_enter() -> None:
    global _MUTE_DEPTH, _MUTE_PREVIOUS
    with _MUTE_LOCK:
        if _MUTE_DEPTH == 0:
            _MUTE_PREVIOUS = sys.unraisablehook
            sys.unraisablehook = _closed_loop_hook
        # every time (addFilter is idempotent): the filter is present while any context is open even if
        # someone removed it meanwhile
        logging.getLogger("asyncio").addFilter(_ORPHAN_FILTER)
        _MUTE_DEPTH += 1


def _mute_exit() -> None:
    global _MUTE_DEPTH, _MUTE_PREVIOUS
    with _MUTE_LOCK:
        _MUTE_DEPTH -= 1
        if _MUTE_DEPTH == 0:
            if sys.unraisablehook is _closed_loop_hook:
                sys.unraisablehook = _MUTE_PREVIOUS
            _MUTE_PREVIOUS = None
            logging.getLogger("asyncio").removeFilter(_ORPHAN_FILTER)


@contextlib.contextmanager
def closed_loop_errors_muted():
    """Within this context, drop the "RuntimeError: Event loop is closed" tracebacks (and only those) that
    ``sys.unraisablehook`` would print, and asyncio's "Task exception was never retrieved" records of abandoned
    tensorstore reads (:class:`_OrphanTaskFilter`; other tasks' records pass).

    When orbax gives up on a damaged checkpoint (or a failed save), tensorstore still completes the
    outstanding reads/writes and their callbacks hit orbax's already closed asyncio loop: each prints such a
    traceback (while orbax gives up, or later). Every other unraisable error goes to the previous hook.
    Reentrant: the hook is installed by the outermost context and the previous one restored when it ends
    (if nobody replaced it meanwhile). A :class:`Checkpointer` holds one open from construction to
    :meth:`~Checkpointer.close`.
    """
    _mute_enter()
    try:
        yield
    finally:
        _mute_exit()


def mute_closed_loop_errors_for_process() -> None:
    """The filter of :func:`closed_loop_errors_muted` for the rest of the process: for an application's entry
    point only (``jaxgest.cli.main``), where such callbacks can still fire at interpreter exit. Library code
    uses the context manager."""
    _mute_enter()


class _SettlingLoop(asyncio.SelectorEventLoop):
    """An event loop that, on :meth:`close`, first lets every task it ran end and retrieves the exceptions of
    all of them: no task is left pending (a suspended read would be finalised later by the garbage collector,
    printing a traceback) and no exception is left unretrieved (asyncio would log it on collection)."""

    def __init__(self, settle_timeout: float = 120.0):
        super().__init__()
        import weakref

        self._settle_timeout = settle_timeout
        self._tasks = weakref.WeakSet()  # every task of this loop (all_tasks() lists only pending ones)
        self.set_task_factory(self._make_task)

    def _make_task(self, loop, coro, **kwargs):
        task = asyncio.Task(coro, loop=loop, **kwargs)
        self._tasks.add(task)
        return task

    def _settle(self) -> None:
        deadline = self.time() + self._settle_timeout
        for _ in range(1000):  # tasks may start further tasks while they end
            pending = [t for t in self._tasks if not t.done()]
            if not pending:
                break
            waiter = asyncio.gather(*pending, return_exceptions=True)
            try:
                self.run_until_complete(asyncio.wait_for(waiter, max(deadline - self.time(), 0.0)))
            except (asyncio.TimeoutError, asyncio.CancelledError):  # a read that never ends: cancel it
                for t in pending:
                    t.cancel()
                with contextlib.suppress(BaseException):
                    self.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
                break
        for t in list(self._tasks):  # mark every exception retrieved (gather did it for those it awaited)
            if t.done() and not t.cancelled():
                t.exception()
        with contextlib.suppress(Exception):
            self.run_until_complete(self.shutdown_asyncgens())
        with contextlib.suppress(Exception):
            self.run_until_complete(self.shutdown_default_executor())

    def close(self) -> None:
        if not self.is_running() and not self.is_closed():
            with contextlib.suppress(Exception):
                self._settle()
        super().close()


class _SettlingPolicy(asyncio.DefaultEventLoopPolicy):
    def new_event_loop(self):
        return _SettlingLoop()


@contextlib.contextmanager
def settled_event_loops():
    """Within this context every new asyncio event loop (orbax creates one per restore/save) lets its pending
    tasks end and retrieves their exceptions before it closes (:class:`_SettlingLoop`): a failed restore leaves
    no pending read behind whose collection would print tracebacks at a random later moment.

    Scoped: the previous event loop policy is put back at the end (reentrant: an inner context does nothing).
    Only the default policy is replaced (another one, e.g. uvloop's, is left alone).
    """
    previous = asyncio.get_event_loop_policy()
    if type(previous) is not asyncio.DefaultEventLoopPolicy:
        yield
        return
    asyncio.set_event_loop_policy(_SettlingPolicy())
    try:
        yield
    finally:
        if isinstance(asyncio.get_event_loop_policy(), _SettlingPolicy):
            asyncio.set_event_loop_policy(previous)

"""One writer per workdir: the exclusive lock every ``train`` holds while it writes.

:func:`exclusive_workdir` takes an ``fcntl.flock`` lock on ``<workdir>/.jaxgest-train.lock`` and writes the
holder into it (``pid <PID> host <HOST> since <UTC time>``). A second writer does not wait: it stops with a
one-line :class:`WorkdirBusy` naming the holder (the command line exits 2). The kernel releases the lock when
its process ends however it ends, so a workdir whose writer was killed (``kill -9``, a power cut) is taken over
at once; because such a process could not clear the file, its holder line is still there and the takeover is
reported in one warning line. A writer that ends normally (also by an error or a handled interrupt) removes
the file (while still holding it; a writer that opened the removed file opens the new one).

Readers (``transfer``, ``generate``, ``evaluate``) take no lock: checkpoints appear by orbax's atomic rename, so
a reader always sees complete ones and restores the newest while a training writes.

In a multi-process run only process 0 takes the lock (the processes write one workdir together).
"""

from __future__ import annotations

import contextlib
import datetime
import os
import pathlib
import socket

from jaxgest.runtime.errors import JaxgestError, WriteError

__all__ = ["LOCK_NAME", "WorkdirBusy", "exclusive_workdir"]

LOCK_NAME = ".jaxgest-train.lock"


class WorkdirBusy(JaxgestError):
    """Another process is training into the workdir."""


def _holder(fd: int) -> str:
    os.lseek(fd, 0, os.SEEK_SET)
    return os.read(fd, 4096).decode("utf-8", "replace").strip()


def _describe(holder: str) -> str:
    """``pid 123 host h since t`` -> ``PID 123 on h since t`` (what the messages say)."""
    parts = holder.split()
    fields = dict(zip(parts[0::2], parts[1::2]))
    if "pid" not in fields:
        return "a process that left no name"
    where = f" on {fields['host']}" if "host" in fields else ""
    since = f", started {fields['since']}" if "since" in fields else ""
    return f"PID {fields['pid']}{where}{since}"


@contextlib.contextmanager
def exclusive_workdir(workdir, *, warn=None, primary: bool = True):
    """Hold the workdir's writer lock for the duration of the context (``workdir`` is created).

    Raises :class:`WorkdirBusy` (one line naming the holder) when another process holds it. ``warn(message)``
    reports the takeover of a lock whose writer is gone (default: :func:`jaxgest.runtime.checkpoint.warn`).
    ``primary=False`` (processes other than 0 of a multi-process run): no lock is taken.
    """
    if not primary:
        yield
        return
    if warn is None:
        from jaxgest.runtime.checkpoint import warn
    workdir = pathlib.Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    path = workdir / LOCK_NAME
    fd = _acquire(workdir, path)
    try:
        left = _holder(fd)
        if left:  # its writer ended without removing it: killed
            warn(f"{workdir}: the training that held this workdir ({_describe(left)}) is gone without "
                 "finishing (killed?); taking over from its last complete checkpoint")
        since = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} host {socket.gethostname()} since {since}\n".encode(), 0)
        try:
            yield
        finally:  # an end through Python (also an error, a handled interrupt) leaves nothing behind; it is
            with contextlib.suppress(OSError):  # removed while still held
                path.unlink()
    finally:
        os.close(fd)  # releases the lock


def _acquire(workdir: pathlib.Path, path: pathlib.Path) -> int:
    """Open and lock ``path``; the file must still be the one at ``path`` once locked (a writer that ended
    meanwhile removed it: open the new one)."""
    import fcntl

    for _ in range(100):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise WriteError(f"{path}: cannot write ({e.strerror or e}); training needs a writable "
                             "workdir") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _describe(_holder(fd))
            os.close(fd)
            raise WorkdirBusy(f"{workdir}: another training is writing to this workdir ({holder}); wait for "
                              "it to end, stop it, or use another --workdir") from None
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)
    raise WorkdirBusy(f"{workdir}: cannot take the writer lock {path.name} (it keeps changing)")

"""Atomic output files: nothing half-written is ever left at a user's path.

Every writer in jaxgest (BVH, WAV, GIF/PNG, JSON, CSV) goes through :func:`atomic_output`: the data is
written to a temporary file in the destination folder, given the permissions a normal file would get
(``0666 & ~umask``), then renamed over the destination with ``os.replace``. On any error the temporary file
is removed and the destination is untouched (a write killed outright leaves its hidden temporary file, which
the next write to the same path removes); an error of the operating system (disk full, read-only folder,
no permission) becomes a one-line :class:`~jaxgest.runtime.errors.WriteError` naming the file.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import pathlib
import tempfile

import numpy as np

from jaxgest.runtime.errors import DataError, WriteError


TMP_MARK = "jaxgest-tmp-"  # temporary files are ``.<stem>.jaxgest-tmp-<pid>-<random><suffix>``


def check_output_path(path) -> pathlib.Path:
    """The output path as a Path; :class:`DataError` when its folder does not exist."""
    path = pathlib.Path(path)
    if not path.parent.is_dir():
        raise DataError(f"{path}: output directory {path.parent} does not exist")
    if path.is_dir():
        raise DataError(f"{path}: is a directory; give a file name")
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_output(path):
    """``with atomic_output(p) as tmp: write(tmp)`` -> ``p`` appears complete or not at all."""
    path = check_output_path(path)
    existed = path.exists()
    suffix = path.suffix or ".tmp"
    remove_stale_temporaries(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.{TMP_MARK}{os.getpid()}-", suffix=suffix,
                                   dir=path.parent)
        os.close(fd)
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except OSError as e:
        raise write_error(path, e, existed) from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            with contextlib.suppress(OSError):
                os.remove(tmp)


def remove_stale_temporaries(path) -> list:
    """Remove the temporary files of earlier writes to ``path`` whose process is gone (killed mid-write:
    SIGKILL or a power cut leave ``.<stem>.jaxgest-tmp-<pid>-*``); returns the removed paths. A temporary of a
    process that is still running (a concurrent write) is left alone."""
    path = pathlib.Path(path)
    removed = []
    pattern = f".{glob.escape(path.stem)}.{TMP_MARK}*-*{glob.escape(path.suffix or '.tmp')}"
    for p in path.parent.glob(pattern):
        pid = p.name[len(f".{path.stem}.{TMP_MARK}"):].split("-", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid() or _alive(int(pid)):
            continue
        with contextlib.suppress(OSError):
            p.unlink()
            removed.append(p)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, another user's
        return True
    return True


def write_error(path, e: OSError, existed: bool = False) -> WriteError:
    """The one-line error of a write to ``path`` that failed with ``e`` (nothing partial is left)."""
    why = e.strerror or str(e) or type(e).__name__
    kept = "the existing file is unchanged" if existed else "no file was written"
    return WriteError(f"{path}: cannot write ({why}); {kept}")


def write_text_atomic(path, text: str) -> pathlib.Path:
    with atomic_output(path) as tmp:
        with open(tmp, "w", newline="") as f:
            f.write(text)
    return pathlib.Path(path)


def json_default(o):
    """``json.dumps(default=...)`` for numpy scalars and arrays, tuples and sets."""
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (tuple, set)):
        return list(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_json_atomic(path, obj) -> pathlib.Path:
    """Write ``obj`` as indented, key-sorted JSON to ``path`` through :func:`atomic_output`."""
    return write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True, default=json_default) + "\n")

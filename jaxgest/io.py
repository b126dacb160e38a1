"""Atomic output files: nothing half-written is ever left at a user's path.

Every writer in jaxgest (BVH, WAV, GIF/PNG, JSON, CSV) goes through :func:`atomic_output`: the data is
written to a temporary file in the destination folder, given the permissions a normal file would get
(``0666 & ~umask``), then renamed over the destination with ``os.replace``. On any error the temporary file
is removed and the destination is untouched.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import tempfile

from jaxgest.errors import DataError


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
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_text_atomic(path, text: str) -> pathlib.Path:
    with atomic_output(path) as tmp:
        with open(tmp, "w", newline="") as f:
            f.write(text)
    return pathlib.Path(path)

"""Why a checkpoint cannot be read or written, in one line, and the content digest that catches corruption.

Used by :class:`jaxgest.runtime.checkpoint.Checkpointer`: :class:`Unreadable` marks a checkpoint step that cannot be
read, :func:`read_reason` / :func:`write_reason` turn orbax/tensorstore/OS errors into a short reason,
:func:`digest` is the sha256 of a pytree's arrays stored in each checkpoint's meta, :func:`tree_shapes`
compares stored and requested structures.
"""

from __future__ import annotations

import json
from typing import Mapping, Optional

import jax
import numpy as np


class Unreadable(Exception):
    """A checkpoint step that cannot be read (truncated/corrupted/missing files): ``reason`` says how."""


def read_reason(e: BaseException) -> str:
    """A short description of why orbax/tensorstore could not read a checkpoint."""
    if isinstance(e, Unreadable):
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


def digest(tree) -> Optional[str]:
    """sha256 of a pytree's arrays (names, shapes, dtypes, bytes; order-independent of the container types),
    saved in a checkpoint's meta and verified on restore: a flipped byte that still decodes is caught too.
    None when an array is not addressable from this process (multi-host sharded state: not checked)."""
    import hashlib

    h = hashlib.sha256()
    try:
        leaves = sorted((path_names(p), x) for p, x in jax.tree_util.tree_flatten_with_path(tree)[0])
        for name, x in leaves:
            a = np.ascontiguousarray(np.asarray(jax.device_get(x)))
            h.update(repr((name, a.shape, a.dtype.str)).encode())
            h.update(a.tobytes())
    except Exception:  # noqa: BLE001  (not fully addressable)
        return None
    return h.hexdigest()


def flat(d: Mapping, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, Mapping):
            out.update(flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def path_names(path) -> tuple:
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


def tree_shapes(tree) -> dict:
    return {path_names(p): tuple(x.shape) for p, x in jax.tree_util.tree_flatten_with_path(tree)[0]}


def write_reason(e: BaseException) -> str:
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
    return read_reason(first)

"""The workdir format: its version, the models a workdir may hold, and the checks of a workdir's config.json.

A workdir (or checkpoint meta) stamped with a newer ``format_version`` than :data:`FORMAT_VERSION` (absent = 1)
or naming a model outside :data:`MODELS` is refused with a one-line :class:`~jaxgest.runtime.errors.CheckpointError`;
:func:`config_diff` names the fields in which a stored config differs from a requested one.
"""

from __future__ import annotations

import json
import pathlib
from typing import Mapping, Optional

from jaxgest.runtime.errors import CheckpointError
from jaxgest.runtime.io import json_default

__all__ = ["FORMAT_VERSION", "MODELS", "check_workdir_config", "config_diff", "normalise"]

FORMAT_VERSION = 1
MODELS = ("tgst", "zeggs")  # what config.json's "model" (earlier TGST workdirs: "kind") may name
"""Workdir format written by this version (``"format_version"`` in config.json and in each checkpoint's meta;
absent = 1). A workdir stamped with a newer version is refused with a one-line error."""


def normalise(obj):
    """JSON round trip so tuples/lists and numpy scalars compare equal to what was stored."""
    return json.loads(json.dumps(obj, sort_keys=True, default=json_default))


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
    model = stored.get("model", stored.get("kind"))  # "kind": TGST workdirs of earlier versions
    if model not in MODELS:
        raise CheckpointError(f"{workdir}: config.json names {'no model' if model is None else repr(model)} "
                              f"(this jaxgest knows {', '.join(MODELS)}): an older layout or not a jaxgest "
                              "workdir; retrain into a new --workdir")
    family = (kind or "").split("_")[0]
    if family in MODELS and model != family:
        raise CheckpointError(f"{workdir}: a {model} workdir, not a {family} one; use another --workdir")
    return stored

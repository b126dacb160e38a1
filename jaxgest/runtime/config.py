"""What both models' configs share: the preset registry lookup and dotted overrides.

A model's configs are nested frozen dataclasses (``Config`` with ``model``, ``train`` and ``inference``
parts, step counts inside ``train``); each model has one registry ``PRESETS: dict[str, Config]``.

An override names a field by its dotted path from the top ``Config`` (``train.autoencoder.learning_rate``,
``model.gru_hidden``) and gives a value; on the command line ``--override KEY=VALUE`` with ``VALUE`` read
as JSON, else as a Python literal, else as a plain string (``3e-4``, ``true``, ``[32, 32]``, ``32,32``,
``"authors"``, ``authors``). Values are checked against the field's current value: a list becomes a tuple
for a tuple field, an int a float for a float field; other type changes are refused. An unknown key is one
line naming the closest field paths.
"""

from __future__ import annotations

import ast
import dataclasses
import difflib
import json
from typing import Any, Mapping, Optional

from jaxgest.runtime.errors import JaxgestError

__all__ = ["apply_overrides", "field_paths", "get_preset", "parse_override", "parse_overrides", "parse_value"]


def get_preset(presets: Mapping[str, Any], name: str, model: str):
    """``presets[name]``; an unknown name is a :class:`JaxgestError` listing the choices."""
    if name not in presets:
        raise JaxgestError(f"unknown {model} preset {name!r} (choose from {', '.join(presets)})")
    return presets[name]


def parse_value(text: str):
    """A command-line value: JSON (``3e-4``, ``true``, ``null``, ``[32, 32]``, ``"x"``), else a Python
    literal (``True``, ``None``, ``(32, 32)``, ``32,32``), else the text itself."""
    try:
        return json.loads(text)
    except ValueError:
        pass
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        return text


def parse_override(item: str) -> tuple[str, Any]:
    """``"train.autoencoder.learning_rate=3e-4"`` -> ``("train.autoencoder.learning_rate", 0.0003)``."""
    key, sep, text = item.partition("=")
    key = key.strip()
    if not sep or not key:
        raise JaxgestError(f"--override {item!r}: expected KEY=VALUE, e.g. train.autoencoder.learning_rate=3e-4")
    return key, parse_value(text.strip())


def parse_overrides(items) -> dict:
    """Several ``KEY=VALUE`` strings -> ``{key: value}`` (a later key wins)."""
    return dict(parse_override(item) for item in items or ())


def field_paths(cfg) -> list[str]:
    """Every leaf field of a nested config dataclass as a dotted path, in field order."""
    out = []
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value):
            out.extend(f"{f.name}.{p}" for p in field_paths(value))
        else:
            out.append(f.name)
    return out


def _close(key: str, paths: list[str]) -> str:
    """`` (closest: a, b)`` -- the paths most like ``key``: by the whole path, then by the last name."""
    leaf = key.rsplit(".", 1)[-1]
    close = [p for p in paths if p.rsplit(".", 1)[-1] == leaf]
    close += [p for p in paths if "".join(w[:1] for w in p.rsplit(".", 1)[-1].split("_")) == leaf]  # lr
    close += difflib.get_close_matches(key, paths, n=3, cutoff=0.6)
    if not close:
        by_leaf: dict[str, list[str]] = {}
        for p in paths:
            by_leaf.setdefault(p.rsplit(".", 1)[-1], []).append(p)
        close = [p for n in difflib.get_close_matches(leaf, list(by_leaf), n=3, cutoff=0.6) for p in by_leaf[n]]
    close = list(dict.fromkeys(close))[:4]
    return f" (closest: {', '.join(close)})" if close else ""


def _coerce(key: str, value, current, optional: bool = False):
    """``value`` as the type of the field's ``current`` value (list -> tuple, int -> float); else an error.
    ``optional`` (an ``Optional[...]`` field): None, ``"none"`` and ``"None"`` give None."""
    if (optional or current is None) and value in (None, "none", "None"):
        return None
    if current is None or value is None:
        return value  # optional fields (e.g. xla_opt_level); the dataclass checks the rest
    if isinstance(current, bool):
        if isinstance(value, bool):
            return value
    elif isinstance(current, tuple):
        if isinstance(value, (list, tuple)):
            return tuple(value)
        if not isinstance(value, (str, bytes)) and isinstance(value, (int, float)) and len(current) == 1:
            return (value,)
        if isinstance(value, str):  # a comma-separated list: exclude_styles=sad,tense
            return tuple(parse_value(x.strip()) for x in value.split(",") if x.strip())
    elif isinstance(current, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif isinstance(current, int):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
    elif isinstance(current, str):
        if isinstance(value, str):
            return value
    else:
        return value
    raise JaxgestError(f"override {key}={value!r}: expected a {type(current).__name__} "
                       f"like the current {current!r}")


def _values(cfg) -> dict:
    """A nested config dataclass as nested dicts of its field values (the leaves untouched)."""
    return {f.name: _values(v) if dataclasses.is_dataclass(v := getattr(cfg, f.name)) else v
            for f in dataclasses.fields(cfg)}


def _rebuild(cfg, values: dict):
    """``cfg``'s classes filled with ``values`` (from :func:`_values`), built bottom-up."""
    return type(cfg)(**{f.name: _rebuild(v, values[f.name]) if dataclasses.is_dataclass(v := getattr(cfg, f.name))
                        else values[f.name] for f in dataclasses.fields(cfg) if f.init})


def apply_overrides(cfg, overrides: Optional[Mapping[str, Any]] = None, *, model: str = "config",
                    forbidden: tuple[str, ...] = ()):
    """``cfg`` (a nested frozen dataclass) with each dotted ``key: value`` of ``overrides`` set.

    All fields are set first and the dataclasses checked once, so fields that must agree (the latent width
    and the token width, say) can change together. Unknown keys, sections given a value, values of another
    type and configs the dataclasses reject are each a one-line :class:`JaxgestError`; ``forbidden`` paths
    (set from the data, e.g. ``model.num_joints``) too.
    """
    if not overrides:
        return cfg
    paths = field_paths(cfg)
    values = _values(cfg)
    for key, value in overrides.items():
        if key in forbidden:
            raise JaxgestError(f"override {key}: set from the data, not overridable")
        if key not in paths:
            section = [p for p in paths if p.startswith(key + ".")]
            if section:
                raise JaxgestError(f"override {key}: a section; set its fields ({', '.join(section[:3])}, ...)")
            raise JaxgestError(f"unknown {model} config field {key!r}{_close(key, paths)}")
        *parents, leaf = key.split(".")
        node, owner = values, cfg
        for name in parents:
            node, owner = node[name], getattr(owner, name)
        annotation = str(next(f.type for f in dataclasses.fields(owner) if f.name == leaf))
        node[leaf] = _coerce(key, value, node[leaf], optional="Optional" in annotation or "None" in annotation)
    try:
        return _rebuild(cfg, values)
    except (TypeError, ValueError) as e:
        raise JaxgestError(f"bad {model} config override ({', '.join(overrides)}): {e}") from None

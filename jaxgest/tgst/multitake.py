"""Multi-take TGST evaluation (Bandai-Namco-2; SPEC §5 "Multi-take data"): splits by take, the pairs of the
three conditions with their ground-truth takes, and the per-pair errors and controls.

* :func:`take_of` / :func:`split_by_take` / :func:`link_split` -- the take number of a Bandai-Namco clip
  (``dataset-2_{content}_{style}_{take}.bvh``), train 001-004 / validate 005 / test 006-008, and a training
  folder of symlinks (no data copied).
* :func:`make_multitake_pairs` -- content = a ``normal`` test take; per target style s and exemplar e (a test
  take of style s): *intra* (e has the content's gesture), *inter-mirror* (e is the other hand's version of
  the same gesture, ``wave-left-hand`` <-> ``wave-right-hand``), *inter-other* (e is another gesture). The
  ground truth is every test take of (content, s) other than the exemplar (never the content clip).
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import re
from collections.abc import Sequence

from jaxgest.errors import DataError

TAKE_RE = re.compile(r"_(\d+)\.bvh$")
SPLITS = {"train": (1, 2, 3, 4), "validate": (5,), "test": (6, 7, 8)}
CONDITIONS = ("intra", "inter-mirror", "inter-other")
NEUTRAL = "normal"
_SIDES = ("left", "right")


def take_of(clip) -> int:
    """The take number of a Bandai-Namco clip (the file name's last ``_NNN``); DataError naming the file."""
    m = TAKE_RE.search(pathlib.Path(clip.path).name)
    if m is None:
        raise DataError(f"{clip.path}: no take number (expected a name ending in _NNN.bvh)")
    return int(m.group(1))


def split_by_take(clips: Sequence, takes: Sequence[int]) -> list:
    """The clips whose take is in ``takes``, in their order."""
    wanted = {int(t) for t in takes}
    return [c for c in clips if take_of(c) in wanted]


def link_split(data_dir, out_dir, takes: Sequence[int], exclude_contents: Sequence[str] = ()) -> int:
    """Fill ``out_dir`` with symlinks to the BVH files of ``data_dir`` (Bandai-Namco layout) whose take is in
    ``takes`` and whose content is not in ``exclude_contents``; stale links are removed. Returns the count.
    DataError when nothing matches or a content to exclude is unknown."""
    from jaxgest.motion import datasets

    root = datasets.dataset_root(data_dir)
    if datasets.detect_layout(root) != "bandai":
        raise DataError(f"{root}: not a Bandai-Namco folder (dataset-N_content_style_NNN.bvh)")
    chosen, contents = [], set()
    for p in sorted(root.glob("*.bvh")):
        m = datasets.BANDAI_RE.match(p.name)
        contents.add(m["content"])
        if int(m["id"]) in {int(t) for t in takes} and m["content"] not in set(exclude_contents):
            chosen.append(p)
    unknown = sorted(set(exclude_contents) - contents)
    if unknown:
        raise DataError(f"{root}: no content {', '.join(unknown)} to hold out (known: {', '.join(sorted(contents))})")
    if not chosen:
        raise DataError(f"{root}: no clip of takes {list(takes)}")
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.bvh"):
        old.unlink()
    for p in chosen:
        os.symlink(p.resolve(), out / p.name)
    return len(chosen)

"""Multi-take TGST evaluation (Bandai-Namco-2; docs/design.md §5 "Multi-take data"): splits by take and the pairs of
the three conditions with their ground-truth takes. The per-pair errors and controls are
:mod:`jaxgest.tgst.multitake_eval`.

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

from jaxgest.runtime.errors import DataError

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


def link_split(data_dir, out_dir, takes: Sequence[int] | None, exclude_contents: Sequence[str] = (),
               clear: bool = True) -> int:
    """Fill ``out_dir`` with symlinks to the BVH files of ``data_dir`` (Bandai-Namco layout) whose take is in
    ``takes`` (None: every take) and whose content is not in ``exclude_contents``; stale links are removed
    first (``clear``; False adds to the folder). Returns the count. DataError when nothing matches or a
    content to exclude is unknown."""
    from jaxgest.motion import datasets

    root = datasets.dataset_root(data_dir)
    if datasets.detect_layout(root) != "bandai":
        raise DataError(f"{root}: not a Bandai-Namco folder (dataset-N_content_style_NNN.bvh)")
    chosen, contents = [], set()
    for p in sorted(root.glob("*.bvh")):
        m = datasets.BANDAI_RE.match(p.name)
        contents.add(m["content"])
        if (takes is None or int(m["id"]) in {int(t) for t in takes}) and m["content"] not in set(exclude_contents):
            chosen.append(p)
    unknown = sorted(set(exclude_contents) - contents)
    if unknown:
        raise DataError(f"{root}: no content {', '.join(unknown)} to hold out (known: {', '.join(sorted(contents))})")
    if not chosen:
        raise DataError(f"{root}: no clip of takes {list(takes)}")
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.bvh") if clear else ():
        old.unlink()
    for p in chosen:
        os.symlink(p.resolve(), out / p.name)
    return len(chosen)


def gesture_of(content: str) -> tuple[str, str | None]:
    """``"wave-left-hand"`` -> ``("wave", "left")``: the gesture and the hand of a one-hand content label
    (the hand None for a label without ``left`` / ``right``)."""
    parts = content.split("-")
    side = next((p for p in parts if p in _SIDES), None)
    return "-".join(p for p in parts if p not in _SIDES), side


def condition_of(content: str, exemplar_content: str) -> str:
    """``"intra"`` (same content label), ``"inter-mirror"`` (same gesture, other hand) or ``"inter-other"``."""
    if content == exemplar_content:
        return "intra"
    (g1, s1), (g2, s2) = gesture_of(content), gesture_of(exemplar_content)
    return "inter-mirror" if g1 == g2 and s1 is not None and s2 is not None and s1 != s2 else "inter-other"


@dataclasses.dataclass(frozen=True, eq=False)
class TakePair:
    """One multi-take evaluation case: ``content`` (a neutral take) in the style of ``exemplar``; the ground
    truth is every clip of ``ground_truths`` (takes of the content's label in the exemplar's style, never the
    exemplar nor the content clip). Fields are dataset Clips."""

    condition: str
    content: object
    exemplar: object
    ground_truths: tuple

    @property
    def style(self) -> str:
        return self.exemplar.style


def make_multitake_pairs(clips: Sequence, takes: Sequence[int] = SPLITS["test"], *, neutral: str = NEUTRAL,
                         exemplar_takes: int | None = None, contents: Sequence[str] | None = None) -> list:
    """The :class:`TakePair` s of the test takes of a multi-take dataset (docs/design.md §5, "Multi-take data").

    Content = a clip of style ``neutral`` whose take is in ``takes`` (and whose label is in ``contents``
    when given); for every other style s and every clip e of style s among ``takes``, the pair
    (content, e) in the condition :func:`condition_of` (content label, e's label); ground truth = every clip of
    (content label, s) among ``takes`` other than e. ``exemplar_takes`` (None = all): per (content clip,
    style, exemplar label) keep that many exemplar takes, rotating with the content clip's take number so
    every take is used (and a ``contents`` subset keeps the pairs of the whole set). Pairs without a ground-truth take are dropped. Ordered by (content, exemplar) path.
    References: Kuriyama et al. 2022, §4.3 (intra / inter-scenario); docs/design.md §5.
    """
    test = sorted(split_by_take(clips, takes), key=lambda c: str(c.path))
    cells: dict = {}
    for c in test:
        cells.setdefault((c.content, c.style), []).append(c)
    heads = [c for c in test if c.style == neutral and (contents is None or c.content in set(contents))]
    styles = sorted({c.style for c in test if c.style != neutral})
    labels = sorted({c.content for c in test})
    pairs = []
    for c in heads:
        k = take_of(c)  # the rotation depends on the clip only, so a content subset keeps its pairs
        for s in styles:
            for label in labels:
                exemplars = cells.get((label, s), [])
                if exemplar_takes is not None and exemplars:
                    n = min(int(exemplar_takes), len(exemplars))
                    exemplars = [exemplars[(k + i) % len(exemplars)] for i in range(n)]
                for e in exemplars:
                    gts = tuple(g for g in cells.get((c.content, s), []) if g is not e and g is not c)
                    if gts:
                        pairs.append(TakePair(condition_of(c.content, e.content), c, e, gts))
    return pairs


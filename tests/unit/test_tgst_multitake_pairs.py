"""Multi-take pairs (Bandai-Namco-2; SPEC §5): splits by take, the three conditions, and ground truths that
are never the exemplar nor the content clip."""

from __future__ import annotations

import itertools
import pathlib

import pytest

from conftest import SHARED
from jaxgest.runtime.errors import DataError
from jaxgest.motion.datasets import Clip, load_folder
from jaxgest.tgst import multitake as mt

CONTENTS = ("raise-up-left-hand", "raise-up-right-hand", "wave-left-hand", "wave-right-hand")
STYLES = ("active", "elderly", "normal")
BANDAI2 = SHARED / "data" / "bandai-namco-2"


def _fake(content, style, take):
    return Clip(None, content, style, pathlib.Path(f"dataset-2_{content}_{style}_{take:03d}.bvh"))


@pytest.fixture(scope="module")
def fakes():
    return [_fake(c, s, t) for c, s, t in itertools.product(CONTENTS, STYLES, range(1, 9))]


def test_conditions_of_one_hand_gestures():
    assert mt.condition_of("wave-left-hand", "wave-left-hand") == "intra"
    assert mt.condition_of("wave-left-hand", "wave-right-hand") == "inter-mirror"
    assert mt.condition_of("wave-left-hand", "raise-up-left-hand") == "inter-other"
    assert mt.condition_of("wave-left-hand", "raise-up-right-hand") == "inter-other"


def test_pairs_never_use_the_exemplar_or_the_content_as_ground_truth(fakes):
    pairs = mt.make_multitake_pairs(fakes)
    assert pairs
    for p in pairs:
        assert p.content.style == "normal" and p.exemplar.style != "normal"
        assert all(g is not p.exemplar and g is not p.content for g in p.ground_truths)
        assert all(g.content == p.content.content and g.style == p.exemplar.style for g in p.ground_truths)
        assert {mt.take_of(x) for x in (p.content, p.exemplar, *p.ground_truths)} <= {6, 7, 8}
        assert p.condition == mt.condition_of(p.content.content, p.exemplar.content)
        # every other test take of (content, style) is a ground truth
        expected = {(6, 7, 8)[i] for i in range(3)} - ({mt.take_of(p.exemplar)} if p.condition == "intra" else set())
        assert {mt.take_of(g) for g in p.ground_truths} == expected
    by = {c: sum(p.condition == c for p in pairs) for c in mt.CONDITIONS}
    # 4 contents x 3 normal test takes x 2 styles x 3 exemplar takes x (1, 1, 2) exemplar contents
    assert by == {"intra": 72, "inter-mirror": 72, "inter-other": 144}


def test_one_exemplar_take_rotates_and_contents_select(fakes):
    pairs = mt.make_multitake_pairs(fakes, exemplar_takes=1, contents=["wave-right-hand"])
    assert {p.content.content for p in pairs} == {"wave-right-hand"} and len(pairs) == 3 * 2 * 4
    assert {mt.take_of(p.exemplar) for p in pairs} == {6, 7, 8}


def test_split_by_take_and_bad_names(fakes):
    train = mt.split_by_take(fakes, mt.SPLITS["train"])
    assert len(train) == len(fakes) // 2 and {mt.take_of(c) for c in train} == {1, 2, 3, 4}
    with pytest.raises(DataError, match="clip.bvh: no take number"):
        mt.take_of(Clip(None, "x", "y", pathlib.Path("clip.bvh")))


def test_real_bandai2_split_and_pairs(tmp_path):
    if not BANDAI2.is_dir():
        pytest.skip(f"real data not found at {BANDAI2}")
    n = mt.link_split(BANDAI2, tmp_path / "split", [1, 2, 3, 4], ["wave-right-hand"])
    assert n == 3 * 7 * 4  # three contents x seven styles x four takes
    names = sorted(p.name for p in (tmp_path / "split").glob("*.bvh"))
    assert all("wave-right-hand" not in x and x[-7:-4] in {"001", "002", "003", "004"} for x in names)
    with pytest.raises(DataError, match="no content nope to hold out"):
        mt.link_split(BANDAI2, tmp_path / "bad", [1], ["nope"])
    two = tmp_path / "two"  # a linked folder loads as a Bandai-Namco dataset
    mt.link_split(BANDAI2, two, [6], ["wave-left-hand", "raise-up-left-hand", "raise-up-right-hand"])
    for p in list(two.glob("*.bvh")):
        if "_normal_" not in p.name and "_active_" not in p.name:
            p.unlink()
    clips = load_folder(two)
    assert [(c.content, c.style, mt.take_of(c)) for c in clips] == [
        ("wave-right-hand", "active", 6), ("wave-right-hand", "normal", 6)]
    assert clips[0].motion.fps == 30.0

"""Per-pair errors of the multi-take evaluation (jaxgest.tgst.multitake.evaluate_pairs) with the session's tiny
TGST model on a few synthetic clips named as Bandai-Namco-2 takes."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from jaxgest.motion.datasets import Clip
from jaxgest.motion.synthetic import render_clip
from jaxgest.tgst import multitake as mt
from jaxgest.tgst import multitake_eval as me
from jaxgest.tgst.api import load_model


@pytest.fixture(scope="module")
def clips():
    out = []
    for content, script in (("wave-left-hand", "greeting"), ("wave-right-hand", "directions")):
        for style, synth in (("normal", "neutral"), ("active", "energetic")):
            for take in (6, 7, 8):
                m = render_clip(script, synth, seed=take, fps=30.0)[0]
                path = pathlib.Path(f"dataset-2_{content}_{style}_{take:03d}.bvh")
                out.append(Clip(m.replace(name=path.name), content, style, path))
    return out


@pytest.mark.slow  # ~2.5 min on the shared CPU (transfers compiled per length bucket)
def test_evaluate_pairs_rows_and_controls(clips, tgst_workdir):
    model = load_model(tgst_workdir)
    pairs = mt.make_multitake_pairs(clips, exemplar_takes=1, contents=["wave-left-hand"])
    assert {p.condition for p in pairs} == {"intra", "inter-mirror"} and len(pairs) == 6
    report = me.evaluate_pairs(model, pairs, methods=("soft", "hard"), pca=me.fit_pca(model, clips),
                               oracle_every=2)
    recs = report["pairs"]
    assert len(recs) == 6 and all("rows" in r for r in recs)
    assert all(0 <= r["swap|mirror"]["step_one"] <= 1 for r in recs)
    for i, r in enumerate(recs):
        rows = r["rows"]
        expected = {"soft|as_is", "hard|as_is", "soft|mirror", "hard|mirror", "autoencoder", "pca16",
                    "content_as_is", "style_as_is", "gt_take", "collage|as_is", "collage|mirror"}
        if i % 2 == 0:
            expected |= {f"oracle_{o}|{v}" for o in ("hands", "rate") for v in ("as_is", "mirror")}
        assert set(rows) == expected
        assert rows["content_as_is"]["content"] == 0.0
        for row in expected - {"collage|as_is", "collage|mirror"}:
            assert all(np.isfinite(rows[row][k]) for k in me.ERRORS), row
        # the mirrored frames only add poses: the collage bound can only go down
        assert rows["collage|mirror"]["content"] <= rows["collage|as_is"]["content"] + 1e-12
        # the gt_take row's ground-truth columns are the take-to-take floor: two real takes of one cell
        assert rows["gt_take"]["gt_content"] < rows["content_as_is"]["gt_content"]
    # the round trip ignores the exemplar: one value per content clip
    by_content = {}
    for r in recs:
        by_content.setdefault(r["content"], set()).add(r["rows"]["autoencoder"]["content"])
    assert all(len(v) == 1 for v in by_content.values())

"""Controls and Table 1 cut the result and the compared clip to a common length, as the authors' evaluator
(``evaluate_distance``: ``content[:clip]``, ``transfer[:clip]``, then the cut at both ends; issue 36, defect b)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxgest import metrics
from jaxgest.motion import bvh
from jaxgest.motion.datasets import load_folder, slice_motion
from jaxgest.motion.synthetic import render_clip, write_dataset
from jaxgest.tgst import evaluate as ev
from jaxgest.tgst import protocol as tp


@pytest.mark.parametrize("protocol", ["authors", "world"])
def test_common_length_features_are_those_of_the_clips_cut_first(protocol):
    long = render_clip("greeting", "energetic", seed=1, fps=60.0)[0]
    short = slice_motion(render_clip("greeting", "neutral", seed=2, fps=60.0)[0], 0, 330)
    a, b = tp.common_length(tp.clip_features(long, protocol=protocol), tp.clip_features(short, protocol=protocol))
    cut_first = tp.clip_features(slice_motion(long, 0, 330), protocol=protocol)
    np.testing.assert_array_equal(a[0], cut_first[0])
    np.testing.assert_array_equal(a[1], cut_first[1])
    full_b = tp.clip_features(short, protocol=protocol)
    np.testing.assert_array_equal(b[0], full_b[0]) and np.testing.assert_array_equal(b[1], full_b[1])


def test_control_errors_use_the_common_length_and_differ_from_the_uncut_ones():
    style = render_clip("directions", "sad", seed=3, fps=60.0)[0]  # 600 frames: the longer clip
    content = slice_motion(render_clip("greeting", "neutral", seed=4, fps=60.0)[0], 0, 300)
    errs = tp.clip_errors(style, content, style)  # "style as is": the style clip taken as the result
    cut = slice_motion(style, 0, 300)
    c, s_ref = tp.clip_features(content), tp.clip_features(style, reference=True)
    assert errs["content"] == metrics.content_error(c[0], tp.clip_features(cut)[0])
    assert errs["style"] == metrics.style_error(tp.clip_features(cut)[1], s_ref[1], 128)
    uncut = tp.features_errors(tp.clip_features(style), c, s_ref, window=128, common=False)
    assert uncut["content"]["mean"] != pytest.approx(errs["content"]["mean"])
    # the world protocol keeps every frame (no common length)
    assert tp.clip_errors(style, content, style, protocol="world")["content"] == metrics.content_error(
        tp.clip_features(content, protocol="world")[0], tp.clip_features(style, protocol="world")[0])


def test_metric_validity_cuts_each_sample_to_the_ground_truths_length(tmp_path):
    write_dataset(tmp_path, clips=14, seconds=8.0, progress=False)
    for clip in load_folder(tmp_path):  # neutral content clips shorter than the others (300 of 480 frames)
        if clip.style.lower() == "neutral":
            bvh.save(slice_motion(clip.motion, 0, 300), clip.path)
    clips = load_folder(tmp_path)
    table = ev.metric_validity(tmp_path, progress=False)
    expected = []
    for p in ev.make_pairs(clips, "inter"):
        g = slice_motion(p.ground_truth.motion, 0, p.content.motion.num_frames)
        expected.append(metrics.content_error(tp.clip_features(g)[0], tp.clip_features(p.content.motion)[0])["mean"])
    assert table["rows"]["content"]["content"]["mean"] == pytest.approx(np.mean(expected))
    assert table["num_evaluated"] == table["num_pairs"] == len(expected)

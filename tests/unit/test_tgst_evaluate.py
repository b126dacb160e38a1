"""Tests of jaxgest.tgst.evaluate: pairs, per-clip errors, evaluate / metric validity, the CLI command."""

from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np
import pytest

import jaxgest.tgst.api
import jaxgest.commands.tgst
from jaxgest import metrics
from jaxgest.runtime.errors import DataError
from jaxgest.motion import bvh
from jaxgest.motion.datasets import Clip, load_folder
from jaxgest.motion.synthetic import write_dataset
from jaxgest.tgst import evaluate as ev

STATS = {"mean", "worst", "w25"}


class IdentityModel:
    """Stand-in for TGSTModel: the result is the content clip (content error 0 by construction)."""

    def transfer(self, content, style, method="soft"):
        return content


class GroundTruthModel:
    """Stand-in for TGSTModel that returns the dataset clip of the content's content in the style's style."""

    def __init__(self, clips):
        self.by_name = {c.motion.name: c for c in clips}
        self.by_key = {(c.content, c.style): c.motion for c in clips}

    def transfer(self, content, style, method="soft"):
        c, s = self.by_name[content.name], self.by_name[style.name]
        return self.by_key[(c.content, s.style)]


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("synthetic")
    # 2 contents x 7 styles, 300 frames at 60 fps: 179 velocities after the authors' 1 s cut (window 128)
    write_dataset(out, clips=14, seconds=5.0, progress=False)
    return out


@pytest.fixture(scope="module")
def clips(data_dir):
    return load_folder(data_dir)


def _fake(content, style, name, take=0):
    return Clip(
        motion=None, content=content, style=style, path=pathlib.Path(f"{content}_{style}_{take}_{name}.bvh")
    )


def test_make_pairs_modes_and_ground_truth():
    clips = [_fake(c, s, "a") for c in ("x", "y", "z") for s in ("Neutral", "happy", "sad")]
    intra = ev.make_pairs(clips, "intra")
    inter = ev.make_pairs(clips, "inter")
    both = ev.make_pairs(clips, "all")
    assert len(intra) == 3 * 2 and len(inter) == 3 * 4 and len(both) == 3 * 6
    for p in both:
        assert p.content.style == "Neutral" and p.style.style != "Neutral"
        assert (p.ground_truth.content, p.ground_truth.style) == (p.content.content, p.style.style)
    assert all(p.content.content == p.style.content for p in intra)
    assert all(p.content.content != p.style.content for p in inter)
    # One take per content and style: the intra ground truth is the style clip itself.
    assert all(p.ground_truth is p.style for p in intra)
    # With a second take, the ground truth is the other take.
    extra = _fake("x", "happy", "b", take=1)
    p = next(p for p in ev.make_pairs(clips + [extra], "intra") if p.style is extra)
    assert p.ground_truth is not extra and p.ground_truth.style == "happy" and p.ground_truth.content == "x"
    # No clip of the content in that style -> no ground truth (ZEGGS-like data).
    lonely = [_fake("x", "normal", "a"), _fake("y", "happy", "a")]
    (q,) = ev.make_pairs(lonely, "inter")
    assert q.ground_truth is None
    assert ev.make_pairs(lonely, "intra") == []


def test_make_pairs_subset_is_seeded_and_ordered():
    clips = [_fake(c, s, "a") for c in "abcd" for s in ("normal", "happy", "sad", "old")]
    key = lambda p: (p.content.path, p.style.path)
    full = [key(p) for p in ev.make_pairs(clips, "all")]
    sub = [key(p) for p in ev.make_pairs(clips, "all", max_pairs=5, seed=3)]
    assert len(sub) == 5 and len(set(sub)) == 5
    assert [full.index(k) for k in sub] == sorted(full.index(k) for k in sub)
    assert sub == [key(p) for p in ev.make_pairs(clips, "all", max_pairs=5, seed=3)]
    assert sub != [key(p) for p in ev.make_pairs(clips, "all", max_pairs=5, seed=4)]
    with pytest.raises(DataError):
        ev.make_pairs(clips, "cross")
    with pytest.raises(DataError):
        ev.make_pairs(clips, "all", max_pairs=-1)
    assert len(ev.make_pairs(clips, "all", max_pairs=0)) == len(ev.make_pairs(clips, "all"))  # 0 = all


def test_clip_errors_identity_and_ground_truth(clips):
    pair = ev.make_pairs(clips, "inter")[0]
    c, s, g = pair.content.motion, pair.style.motion, pair.ground_truth.motion
    errs = ev.clip_errors(c, c, s, g)
    assert set(errs) == {"content", "style", "gt_content", "gt_style"}
    assert all(set(v) == STATS for v in errs.values())
    assert errs["content"] == {"mean": 0.0, "worst": 0.0, "w25": 0.0}
    assert errs["style"]["mean"] > 0 and errs["gt_content"]["mean"] > 0
    copy = ev.clip_errors(g, c, s, g)
    assert copy["gt_content"]["worst"] == 0.0 and copy["gt_style"]["worst"] == 0.0
    assert set(ev.clip_errors(c, c, s)) == {"content", "style"}


def test_clip_errors_match_metrics_on_hand_and_arm_features(clips):
    pair = ev.make_pairs(clips, "inter")[1]
    c, s = pair.content.motion, pair.style.motion
    from jaxgest.motion import kinematics

    # world protocol: world positions, F backward differences, no cut, no mirror (earlier runs)
    hands_c, arms_c = ev.clip_features(c, protocol="world")
    hands_s, arms_s = ev.clip_features(s, protocol="world")
    assert hands_c.shape == (c.num_frames, 6) and arms_c.shape == (c.num_frames, 24)
    pos = kinematics.forward_kinematics(s)
    np.testing.assert_allclose(hands_s[:, 3:], pos[:, s.skeleton.index("Hand_R")] / 100.0)
    errs = ev.clip_errors(s, c, s, protocol="world")
    assert errs["content"] == metrics.content_error(hands_c, hands_s)
    assert errs["style"] == metrics.style_error(arms_s, arms_s, metrics.window_for_fps(s.fps))
    assert errs["style"]["worst"] == 0.0
    # authors' protocol: root-local positions cut by 1 s (60 frames) at both ends, F - 1 forward differences
    hands_a, arms_a = ev.clip_features(s)
    assert hands_a.shape == (s.num_frames - 120, 6) and arms_a.shape == (s.num_frames - 121, 24)
    local = kinematics.root_local_positions(s)[60:-60]
    np.testing.assert_allclose(hands_a[:, 3:], local[:, s.skeleton.index("Hand_R")] / 100.0)
    arm = [s.skeleton.index(n) for n in ("Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L")]
    np.testing.assert_allclose(arms_a[:, :12], (np.diff(local[:, arm], axis=0) * s.fps / 100.0).reshape(-1, 12))
    # the style reference is the clip followed by its mirror: 2F - 30 frames before the cut
    ref_hands, ref_arms = ev.clip_features(s, reference=True)
    assert len(ref_hands) == 2 * s.num_frames - 30 - 120 and len(ref_arms) == len(ref_hands) - 1
    errs = ev.clip_errors(s, c, s)
    assert errs["content"] == metrics.content_error(ev.clip_features(c)[0], hands_a)
    assert errs["style"] == metrics.style_error(arms_a, ref_arms, 128)
    assert errs["style"]["worst"] == 0.0  # every window of the clip is one of its reference's windows


@pytest.mark.parametrize("protocol", ["authors", "world"])
def test_evaluate_identity_model_schema_and_zero_content_error(clips, data_dir, protocol):
    report = ev.evaluate(
        "unused", data_dir, pairs="intra", methods=("soft", "adain"), model=IdentityModel(), progress=False,
        protocol=protocol,
    )
    assert report["pairs"] == "intra" and report["num_pairs"] == 12 == len(report["per_pair"])
    assert report["protocol"]["name"] == protocol and report["notes"]["protocol"].startswith(protocol)
    assert set(report["methods"]) == {"soft", "adain"} and set(report["controls"]) == set(ev.CONTROLS)
    for summary in [*report["methods"].values(), *report["controls"].values()]:
        assert summary["protocol"] == protocol
        assert summary["num_gt"] == 12 and summary["num_evaluated"] == 12 and summary["num_skipped"] == 0
        for k in ("content", "style", "gt_content", "gt_style"):
            assert set(summary[k]) == STATS
            assert summary[k]["mean"] <= summary[k]["w25"] <= summary[k]["worst"]
    for summary in [*report["methods"].values(), report["controls"]["content_as_is"]]:
        assert summary["content"] == {"mean": 0.0, "worst": 0.0, "w25": 0.0}
        assert summary["style"]["mean"] > 0
    # the identity "transfer" is the content as is; the style as is has no style error
    assert report["methods"]["soft"]["style"] == report["controls"]["content_as_is"]["style"]
    assert report["controls"]["style_as_is"]["style"]["worst"] == 0.0
    assert report["swap_diagnostics"] is None and report["bucket"] is None  # not a TGSTModel
    rec = report["per_pair"][0]
    assert set(rec) == {"content", "style", "style_label", "ground_truth", "errors", "controls"}
    assert set(rec["errors"]) == {"soft", "adain"}
    json.dumps(report)  # JSON-serialisable as is
    # The per-method average is the average of the per-pair errors.
    means = [r["errors"]["soft"]["style"]["mean"] for r in report["per_pair"]]
    assert report["methods"]["soft"]["style"]["mean"] == pytest.approx(np.mean(means))
    table = ev.markdown_table(report)
    assert f"| Soft swap (ours) | {protocol} | 12 | 0 | 0 | 0 |" in table
    assert f"| Content as is (control) | {protocol} | 12 |" in table


def test_evaluate_ground_truth_copy_has_zero_ground_truth_error(clips, data_dir):
    report = ev.evaluate(
        "unused",
        data_dir,
        pairs="inter",
        methods=("hard",),
        max_pairs=4,
        model=GroundTruthModel(load_folder(data_dir)),
        progress=False,
    )
    assert report["num_pairs"] == 4
    s = report["methods"]["hard"]
    assert s["gt_content"]["worst"] == 0.0 and s["gt_style"]["worst"] == 0.0
    assert s["content"]["mean"] > 0


def test_evaluate_contents_filter_and_errors(data_dir):
    report = ev.evaluate(
        "unused",
        data_dir,
        pairs="all",
        methods=("soft",),
        contents=["greeting"],
        model=IdentityModel(),
        progress=False,
    )
    assert report["num_pairs"] == 12
    assert all("greeting_neutral" in r["content"] for r in report["per_pair"])
    with pytest.raises(DataError, match="no clips with content"):
        ev.evaluate("unused", data_dir, contents=["nope"], model=IdentityModel(), progress=False)
    with pytest.raises(DataError, match="unknown method"):
        ev.evaluate("unused", data_dir, methods=("soft", "fancy"), model=IdentityModel(), progress=False)


@pytest.mark.parametrize("protocol", ["authors", "world"])
def test_metric_validity_is_table_1_of_the_pairs(data_dir, clips, protocol):
    table = ev.metric_validity(data_dir, progress=False, protocol=protocol)
    assert table["pairs"] == "inter" and table["num_pairs"] == 12 == table["num_evaluated"]
    assert table["protocol"] == protocol
    rows = table["rows"]
    assert set(rows) == {"content", "style"} and all(set(r) == {"content", "style"} for r in rows.values())
    md = ev.validity_table(table).splitlines()
    assert len(md) == 4 and md[2].startswith(f"| Content | {protocol} |") and md[3].startswith("| Style |")
    # Recompute row "style", column "style" directly from the metric functions.
    expected = []
    for p in ev.make_pairs(clips, "inter"):
        g = ev.clip_features(p.ground_truth.motion, protocol=protocol, reference=True)
        x = ev.clip_features(p.style.motion, protocol=protocol)
        expected.append(metrics.style_error(x[1], g[1], 128)["mean"])
    assert rows["style"]["style"]["mean"] == pytest.approx(np.mean(expected))
    # Content validity (Table 1): the content clip's hands are closer to the ground truth than the style clip's.
    # (The style-error ordering of Table 1 does not hold on average for these short inter-scenario synthetic
    # pairs: for the milder styles the content dominates the arm-velocity statistics.)
    assert rows["content"]["content"]["mean"] < rows["style"]["content"]["mean"]
    with pytest.raises(DataError, match="no intra pairs with a ground-truth clip distinct"):
        ev.metric_validity(data_dir, pairs="intra", progress=False)


def test_cli_writes_json_and_prints_table(data_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(jaxgest.tgst.api, "load_model", lambda workdir: IdentityModel(), raising=False)
    parser = argparse.ArgumentParser()
    jaxgest.commands.tgst.register_evaluate(parser.add_subparsers())
    out = tmp_path / "eval.json"
    argv = f"evaluate --workdir {tmp_path} --data {data_dir} --json {out} --pairs inter --methods soft,hard"
    args = parser.parse_args(argv.split() + ["--max-pairs", "3", "--validity"])
    assert args.func(args) == 0
    report = json.loads(out.read_text())
    assert report["num_pairs"] == 3 and set(report["methods"]) == {"soft", "hard"}
    printed = capsys.readouterr().out
    assert "| Soft swap (ours) | authors | 3 | 0 | 0 | 0 |" in printed and "Hard swap (19)" in printed
    assert "protocol authors" in printed and report["protocol"]["name"] == "authors"
    assert report["metric_validity"]["protocol"] == "authors"
    assert report["metric_validity"]["pairs"] == "inter" and "| Content |" in printed
    assert set(report["notes"]) >= {"content", "style", "w25"}
    assert not list(tmp_path.glob(".eval.*"))  # no temporary file left behind
    # --protocol world and --trim are named in the report and the table
    argv = f"evaluate --workdir {tmp_path} --data {data_dir} --json {out} --pairs inter --methods soft"
    args = parser.parse_args(argv.split() + ["--max-pairs", "2", "--protocol", "world", "--trim", "0.5"])
    assert args.func(args) == 0
    report = json.loads(out.read_text())
    assert report["protocol"]["name"] == "world(trim 0.5 s)" and report["protocol"]["root_local"] is False
    assert "| Soft swap (ours) | world(trim 0.5 s) | 2 |" in capsys.readouterr().out
    bad = parser.parse_args(
        f"evaluate --workdir w --data {data_dir} --json {tmp_path}/missing/x.json".split()
    )
    with pytest.raises(DataError, match="does not exist"):
        bad.func(bad)


def test_short_clips_are_skipped(tmp_path):
    write_dataset(tmp_path, clips=2, seconds=3.0, progress=False)  # 180 frames: 119 velocities after the cut

    class NeverCalled:
        def transfer(self, content, style, method="soft"):
            raise AssertionError("a pair too short to evaluate must not be transferred")

    report = ev.evaluate(
        "unused", tmp_path, pairs="intra", methods=("soft",), model=NeverCalled(), progress=False
    )
    s = report["methods"]["soft"]
    assert report["num_pairs"] == 1 and s["num_skipped"] == 1 and s["content"] is None
    assert "shorter than one style window of 128" in report["per_pair"][0]["errors"]["soft"]["skipped"]
    assert report["controls"]["content_as_is"]["num_skipped"] == 1
    # under the world protocol (no cut) the same 180-frame clips are long enough
    with pytest.raises(AssertionError, match="must not be transferred"):
        ev.evaluate("unused", tmp_path, pairs="intra", methods=("soft",), model=NeverCalled(), progress=False,
                    protocol="world")
    # a cut longer than the clip is a skip with the reason, not an error
    report = ev.evaluate("unused", tmp_path, pairs="intra", methods=("soft",), model=NeverCalled(),
                         progress=False, trim_seconds=2.0)
    assert report["protocol"]["name"] == "authors(trim 2 s)"
    assert "too short to cut 120 frames" in report["per_pair"][0]["errors"]["soft"]["skipped"]


def test_model_data_errors_are_skipped(data_dir):
    class Picky:
        def transfer(self, content, style, method="soft"):
            if method == "hard":
                raise DataError("clip too short for the tokenizer")
            return content

    report = ev.evaluate(
        "unused",
        data_dir,
        pairs="intra",
        methods=("soft", "hard"),
        max_pairs=2,
        model=Picky(),
        progress=False,
    )
    assert report["methods"]["hard"]["num_skipped"] == 2 and report["methods"]["hard"]["content"] is None
    assert report["methods"]["soft"]["num_evaluated"] == 2


def test_real_bandai_pairs_and_errors(bandai_dir):
    from jaxgest.motion.datasets import BANDAI_RE

    names = sorted(p.name for p in bandai_dir.glob("*.bvh"))
    fake = [Clip(None, m["content"], m["style"], bandai_dir / n) for n in names if (m := BANDAI_RE.match(n))]
    intra = ev.make_pairs(fake, "intra")
    assert intra and all(p.content.style == "normal" and p.ground_truth is not None for p in intra)
    # bow in normal style -> bow in angry style: the rig's hands/arms are found through its joint map (30 fps).
    c = bvh.load(bandai_dir / "dataset-1_bow_normal_001.bvh")
    s = bvh.load(bandai_dir / "dataset-1_bow_angry_001.bvh")
    errs = ev.clip_errors(c, c, s, s)
    assert errs["content"]["worst"] == 0.0 and errs["gt_style"]["mean"] == errs["style"]["mean"] > 0
    hands, arms = ev.clip_features(c)  # authors' protocol: 30 frames (1 s at 30 fps) cut at both ends
    assert hands.shape == (c.num_frames - 60, 6) and arms.shape == (c.num_frames - 61, 24)
    # root-local positions keep every distance: the hands are as far apart as in the world (metres, not cm)
    world, _ = ev.clip_features(c, protocol="world")
    gap = np.linalg.norm(hands[:, 3:] - hands[:, :3], axis=1)
    np.testing.assert_allclose(gap, np.linalg.norm(world[30:-30, 3:] - world[30:-30, :3], axis=1), atol=1e-9)
    assert 0.1 < gap.max() < 3.0


def test_real_zeggs_features(zeggs_dir):
    m = bvh.load(zeggs_dir / "067_Speech_2_x_1_0.bvh")
    m = m.replace(rotations=m.rotations[:300], translations=m.translations[:300])
    hands, arms = ev.clip_features(m, protocol="world")
    assert hands.shape == (300, 6) and arms.shape == (300, 24)
    assert np.all(np.isfinite(arms)) and 0.3 < np.abs(hands[:, 3:] - hands[:, :3]).max() < 3.0


class StyleRecordingModel:
    """Stand-in that records the style clip it is given (frames, name) and returns the content."""

    def __init__(self):
        self.styles = []

    def transfer(self, content, style, method="soft"):
        self.styles.append(style)
        return content


def test_evaluate_gives_the_model_the_style_input_it_names(clips, data_dir):
    """``style_input="mirror"`` (default, as the authors' evaluator and tgst transfer): the model gets each style
    clip followed by its mirror (jaxgest.tgst.protocol.style_input_clip); ``"as-is"``: the clip itself. The
    errors are scored against the same references either way; the report names the input."""
    from jaxgest.tgst.protocol import style_input_clip

    runs = {}
    for given in ("mirror", "as-is"):
        model = StyleRecordingModel()
        report = ev.evaluate("unused", data_dir, pairs="intra", methods=("soft",), model=model, progress=False,
                             max_pairs=3, style_input=given)
        assert report["style_input"] == given and len(model.styles) == report["num_pairs"] == 3
        runs[given] = (model.styles, report)
    dataset = {c.motion.name: c.motion for c in clips}
    for as_is, mirrored in zip(runs["as-is"][0], runs["mirror"][0]):  # the same pairs in the same order
        np.testing.assert_array_equal(as_is.rotations, dataset[as_is.name].rotations)  # the dataset's clip
        expected = style_input_clip(as_is, "mirror")
        assert mirrored.num_frames == expected.num_frames > as_is.num_frames
        np.testing.assert_allclose(mirrored.rotations, expected.rotations, atol=1e-6)
    # the controls do not depend on the model's input
    for k in ev.CONTROLS:
        assert runs["mirror"][1]["controls"][k]["style"] == runs["as-is"][1]["controls"][k]["style"]
    with pytest.raises(DataError, match="style"):
        ev.evaluate("unused", data_dir, model=StyleRecordingModel(), progress=False, style_input="flipped")

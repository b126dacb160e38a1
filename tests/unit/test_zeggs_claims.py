"""Unit tests of the measures of ZeroEGGS's claims on the generated motion (jaxgest.zeggs.claims): each measure on
constructed inputs, and the whole evaluation with the generated motion replaced by real motion -- it must hold for
GT and FAIL for mismatched real motion (MM) and for damped motion."""

from __future__ import annotations

import numpy as np
import pytest

from jaxgest.runtime.errors import DataError
from jaxgest.zeggs import claims, claims_run, style_judge


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    """Training scripts (synth seed 0) and one held-out script set (seed 1): 2 contents x 7 styles x 6 s."""
    from jaxgest.motion.datasets import load_folder
    from jaxgest.motion.synthetic import write_dataset

    root = tmp_path_factory.mktemp("claims")
    write_dataset(root / "train", clips=14, seconds=6, seed=0, progress=False)
    write_dataset(root / "held", clips=14, seconds=6, seed=1, progress=False)
    return load_folder(root / "train"), [("held", load_folder(root / "held"))]


def test_interval_units():
    one = claims.interval([0.2, 0.4, 0.6], ["a", "a", "a"])
    assert one["unit"] == "clip" and one["mean"] == pytest.approx(0.4) and one["n"] == 3
    two = claims.interval([0.0, 1.0, 1.0, 1.0], ["a", "a", "b", "b"])  # dataset means 0.5 and 1.0
    assert two["unit"] == "dataset" and two["mean"] == pytest.approx(0.75) and two["n"] == 2
    assert two["low"] < 0.75 < two["high"]
    assert claims.interval([np.nan, 1.0], ["a", "a"])["mean"] == 1.0  # a clip without beats is skipped


def test_embedding_collapse_separates_and_collapses():
    rng = np.random.default_rng(0)
    train = {"a": rng.normal(0, 0.1, (50, 4)), "b": rng.normal(0, 0.1, (50, 4)) + [3, 0, 0, 0]}
    far = claims.embedding_collapse(train, rng.normal(0, 0.1, (20, 4)) + [0, 3, 0, 0])
    assert far["separation"] > 5 and far["windows"] == 20
    on_b = claims.embedding_collapse(train, rng.normal(0, 0.1, (20, 4)) + [3, 0, 0, 0])
    assert on_b["separation"] < 1.5 and on_b["nearest_style_counts"] == {"b": 20}
    with pytest.raises(DataError, match="expected"):
        claims.embedding_collapse(train, np.zeros((3, 5)))


def test_zero_shot_rule():
    portrayal = {"per_style": {"sad": {"generated": 0.3, "gt": 0.8, "mm": 0.0, "ratio": 0.375}}}
    assert not claims.zero_shot(portrayal, "sad")["holds"]  # 0.3 < 0.5 x 0.8
    portrayal["per_style"]["sad"].update(generated=0.5, ratio=0.625)
    assert claims.zero_shot(portrayal, "sad")["holds"]
    emb = {"sad": np.zeros((5, 2)), "tense": np.zeros((5, 2)) + 0.01, "calm": np.ones((5, 2))}
    assert not claims.zero_shot(portrayal, "sad", emb)["holds"]  # collapsed onto "tense"
    with pytest.raises(DataError, match="no held-out clip"):
        claims.zero_shot(portrayal, "proud")


def test_window_statistics_shape(sets):
    train, _ = sets
    m = train[0].motion
    w = style_judge.window_statistics(m)
    assert w.shape == (1 + int((m.num_frames - 2 * m.fps) // (0.5 * m.fps)), 12 * m.skeleton.num_joints)


def test_claim_items_partners(sets):
    train, held = sets
    items = claims.claim_items(train, held)
    assert len(items) == 14
    for it in items:
        assert it.example.style == it.clip.style and it.example.content != it.clip.content
        assert it.mm_style.content == it.clip.content and it.mm_style.style != it.clip.style
        assert it.mm_script.content == it.clip.content and it.mm_script.style == it.clip.style
        assert it.mm_script.path != it.clip.path
    with pytest.raises(DataError, match="style 'sad' has no clip in the training data"):
        claims.claim_items([c for c in train if c.style != "sad"], held)


def test_gt_holds_and_mm_fails(sets):
    train, held = sets
    gt = claims_run.evaluate_claims(None, train, held, substitute="gt")
    sp = gt["style_portrayal"]
    assert sp["holds"] and sp["ratio_to_gt"] == 1.0 and sp["gt"]["mean"] > sp["mm"]["mean"] + 0.3
    assert gt["realism"]["holds"] and gt["realism"]["geometric_mean_ratio"] < 1e-3  # the real clips themselves
    # MM of another style: the classifier's accuracy collapses and the style claim fails
    mm = claims_run.evaluate_claims(None, train, held, substitute="mm-style")
    assert not mm["style_portrayal"]["holds"]
    assert mm["style_portrayal"]["generated"]["mean"] < 0.5 * sp["generated"]["mean"]
    # MM of another script: appropriateness cannot beat itself
    mm = claims_run.evaluate_claims(None, train, held, substitute="mm-script")
    ap = mm["appropriateness"]
    assert not ap["holds"] and ap["generated_minus_mm"]["mean"] == 0.0
    md = claims_run.markdown({"claims": mm})
    assert "does not hold" in md and "| sad |" in md
    # the hand-speed diagnostic: GT against itself is 1 in every style
    hs = gt["hand_speeds"]
    assert hs["ratio"]["mean"] == pytest.approx(1.0) and hs["left_share"]["generated"] == hs["left_share"]["gt"]
    assert all(d["ratio"] == pytest.approx(1.0) for d in hs["per_style"].values())
    assert "Hand speed generated / GT" in md


def test_classifier_is_not_decided_by_rounding_noise_channels(sets):
    """Planted feet are constant in the real clips up to rounding (std ~1e-8): a 1 mm jitter of the feet must
    not decide the style (it did with the std floored at 1e-8: every window went to one style)."""
    from jaxgest.motion import body

    train, held = sets
    items = claims.claim_items(train, held)
    rng = np.random.default_rng(0)

    def jittered(m):
        t = m.translations.copy()
        feet = body.joint_indices(m.skeleton, ("Foot_L", "Foot_R"))
        t[:, feet] += rng.normal(0.0, 0.1, (m.num_frames, len(feet), 3))  # 1 mm in file units (cm)
        return m.replace(translations=t)

    motions = [jittered(it.clip.motion) for it in items]

    def accuracy(clf, ms):
        return np.mean([claims.clip_accuracy(p, it.clip.style) for p, it in zip(clf.predict(ms), items)])

    floored, raw = style_judge.StyleClassifier.fit(train), style_judge.StyleClassifier.fit(train, floor_fraction=1e-12)
    gt = accuracy(floored, [it.clip.motion for it in items])
    assert gt > 0.6 and accuracy(raw, [it.clip.motion for it in items]) == pytest.approx(gt, abs=0.1)
    assert accuracy(floored, motions) > gt - 0.1  # the jitter changes nothing that matters
    assert accuracy(raw, motions) < 0.5 * gt  # the defect the floor removes
    floor = style_judge.group_std_floor(floored.features)
    assert floor.shape == floored.features.shape[1:] and np.all(floor > 0)
    with pytest.raises(DataError, match="groups"):
        style_judge.group_std_floor(np.zeros((3, 10)))


def test_damped_motion_fails_realism_and_style(sets):
    train, held = sets

    def frozen(items):  # the first pose held still: no gesture at all
        out = []
        for it in items:
            m = it.clip.motion
            out.append(m.replace(rotations=np.repeat(m.rotations[:1], m.num_frames, 0),
                                 translations=np.repeat(m.translations[:1], m.num_frames, 0)))
        return out

    r = claims_run.evaluate_claims(None, train, held, generate=frozen)
    assert not r["realism"]["holds"] and r["realism"]["geometric_mean_ratio"] > 2.0
    assert not r["style_portrayal"]["holds"]
    assert not r["appropriateness"]["holds"] or r["appropriateness"]["clips_without_beats"] > 0
    assert r["hand_speeds"]["ratio"]["mean"] < 0.01  # frozen: no hand moves


def test_hand_speeds_measure_damping_and_handedness(sets):
    train, held = sets
    items = claims.claim_items(train, held)

    def damped(it):  # played at half speed (each frame twice): the hands move half as fast
        m = it.clip.motion
        i = np.arange(m.num_frames) // 2
        return m.replace(rotations=m.rotations[i], translations=m.translations[i])

    hs = claims.hand_speeds(items, [damped(it) for it in items])
    assert 0.4 < hs["ratio"]["mean"] < 0.6 and all(d["ratio"] < 0.7 for d in hs["per_style"].values())
    swapped = claims.hand_speeds(items, [it.mm_style.motion for it in items])
    left_handed = [s for s in hs["per_style"] if "left" in s]
    if left_handed:  # real left-handed GT moves the left hand more than the right
        d = hs["per_style"][left_handed[0]]["gt"]
        assert d["left"] > d["right"]
    assert swapped["left_share"]["gt"] == hs["left_share"]["gt"]
    with pytest.raises(DataError):
        claims.hand_speeds(items, [])


def test_substitute_and_model_errors(sets):
    train, held = sets
    with pytest.raises(DataError, match="unknown substitute"):
        claims_run.evaluate_claims(None, train, held, substitute="nope")
    with pytest.raises(DataError, match="no model"):
        claims_run.evaluate_claims(None, train, held)


def test_style_scale_reaches_the_generator(sets, monkeypatch):
    """--style-scale A generates with the example's embedding times A (blend weights [A], unnormalised)."""
    train, held = sets
    items = claims.claim_items(train, held)[:2]
    calls = []

    class Fake:
        def generate(self, audio, styles, *, weights=None, sr=None, seed=0, name=None):
            calls.append((len(styles), list(weights)))
            return styles[0]

    monkeypatch.setattr("jaxgest.motion.datasets.load_clip_audio", lambda clip: (np.zeros(160), 16000))
    out = claims_run.generate_items(Fake(), items, style_scale=1.5)
    assert len(out) == 2 and calls == [(1, [1.5]), (1, [1.5])]
    with pytest.raises(DataError, match="--style-scale"):
        claims_run.run("nowhere", "nowhere", heldout_seeds=1, style_scale=0.0)


def test_speech_segments(tmp_path):
    import soundfile as sf

    sf.write(tmp_path / "a.wav", np.zeros(16000 * 25, np.float32), 16000)
    segs = claims_run.speech_segments(tmp_path / "a.wav", 10.0)
    assert [round(s[2]) for s in segs] == [0, 10, 20] and len(segs[-1][0]) == 16000 * 5
    assert len(claims_run.speech_segments(tmp_path / "a.wav", 60.0)) == 1  # shorter than one segment: one


def test_exclude_styles_data_and_override(sets):
    from jaxgest.zeggs import data as zdata
    from jaxgest.runtime.config import apply_overrides, parse_overrides
    from jaxgest.zeggs.config import Config

    train, _ = sets
    kept = zdata.exclude_styles(train, ("sad", "tense"), "D")
    assert {c.style for c in kept} == {c.style for c in train} - {"sad", "tense"}
    assert zdata.exclude_styles(train, (), "D") == list(train)
    with pytest.raises(DataError, match="D: exclude_styles names style\\(s\\) the data does not have: happy"):
        zdata.exclude_styles(train, ("happy",), "D")
    with pytest.raises(DataError, match="leaves no clip"):
        zdata.exclude_styles(train, tuple({c.style for c in train}), "D")
    cfg = apply_overrides(Config(), parse_overrides(["train.exclude_styles=sad,left_handed"]), model="ZeroEGGS")
    assert cfg.train.exclude_styles == ("sad", "left_handed")


@pytest.mark.slow
def test_full_size_substitutes(tmp_path_factory):
    """At the experiment's size (6 contents x 7 styles x 10 s; two held-out script sets): GT passes every claim,
    MM of another style fails style portrayal, MM of another script fails appropriateness."""
    from jaxgest.motion.datasets import load_folder
    from jaxgest.motion.synthetic import write_dataset

    root = tmp_path_factory.mktemp("claims_full")
    for k in range(3):
        write_dataset(root / f"seed{k}", seed=k, progress=False)
    train = load_folder(root / "seed0")
    held = [(f"seed{k}", load_folder(root / f"seed{k}")) for k in (1, 2)]
    gt = claims_run.evaluate_claims(None, train, held, substitute="gt")
    assert gt["style_portrayal"]["holds"] and gt["realism"]["holds"] and gt["appropriateness"]["holds"]
    assert not claims_run.evaluate_claims(None, train, held, substitute="mm-style")["style_portrayal"]["holds"]
    assert not claims_run.evaluate_claims(None, train, held, substitute="mm-script")["appropriateness"]["holds"]

"""Built-in synthetic data: determinism, every content x style, styles differ as their parameters say,
strokes on audio onsets, feet on the floor, dataset writing."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from jaxgest.motion import synthetic as syn
from jaxgest.motion.synthetic import CONTENTS, STYLES, ContentSpec, StyleParams, make_script, render_clip

FPS = 60.0


def _short(name, seconds=4.0):
    return CONTENTS[name].with_seed(0, seconds)


@pytest.fixture(scope="module")
def fk():
    from jaxgest.motion.kinematics import forward_kinematics

    return lambda m: np.asarray(forward_kinematics(m), dtype=np.float64)


def _hands(m, fk):
    p = fk(m)
    sk = m.skeleton
    return p[:, sk.index("Hand_L")], p[:, sk.index("Hand_R")]


def _speed(x):
    return np.linalg.norm(np.diff(x, axis=0), axis=-1) * FPS


def test_catalogue():
    assert len(STYLES) >= 6 and len(CONTENTS) >= 6
    kinds = {k for c in CONTENTS.values() for k, _ in c.strokes}
    assert kinds == set(syn.STROKE_TYPES)
    for s in STYLES.values():
        assert dataclasses.is_dataclass(s) and s.name in STYLES
    with pytest.raises(dataclasses.FrozenInstanceError):
        STYLES["neutral"].amplitude = 2.0


def test_determinism():
    spec = _short("story", 3.0)
    m1, a1, sr1 = render_clip(spec, "tense", seed=3)
    m2, a2, sr2 = render_clip(spec, "tense", seed=3)
    np.testing.assert_array_equal(m1.rotations, m2.rotations)
    np.testing.assert_array_equal(m1.translations, m2.translations)
    np.testing.assert_array_equal(a1, a2)
    assert sr1 == sr2 == 16000
    m3, a3, _ = render_clip(spec, "tense", seed=4)
    assert np.abs(m3.rotations - m1.rotations).max() > 1e-3  # the performance noise changes
    np.testing.assert_array_equal(a3, a1)  # the content (audio, strokes) does not
    other = spec.with_seed(1, 3.0)
    assert make_script(other).strokes != make_script(spec).strokes
    assert not np.array_equal(render_clip(other, "tense", seed=3)[1], a1)


def test_every_content_in_every_style(fk):
    for c in CONTENTS:
        spec = _short(c, 3.0)
        audio0 = None
        for s in STYLES:
            m, audio, sr = render_clip(spec, s, seed=0)
            assert m.num_frames == 180 and m.fps == FPS and m.skeleton.num_joints == 21
            assert np.all(np.isfinite(m.rotations)) and np.all(np.isfinite(m.translations))
            np.testing.assert_allclose(np.linalg.norm(m.rotations, axis=-1), 1.0, atol=1e-9)
            # continuous rotations: no frame-to-frame jump above 25 degrees on any joint
            dots = np.abs(np.sum(m.rotations[1:] * m.rotations[:-1], axis=-1))
            assert np.degrees(2 * np.arccos(np.clip(dots, 0, 1))).max() < 25.0
            assert audio.dtype == np.float32 and audio.shape == (3 * sr,) and np.abs(audio).max() <= 1.0
            if audio0 is None:
                audio0 = audio
            np.testing.assert_array_equal(audio, audio0)  # one audio per content, in every style


def test_upright_facing_camera_feet_on_floor(fk):
    m, _, _ = render_clip(_short("celebration", 6.0), "energetic", seed=1)
    p = fk(m)
    sk = m.skeleton
    i = sk.index
    feet = p[:, [i("Foot_L"), i("Toes_L"), i("Foot_R"), i("Toes_R")], 1]
    np.testing.assert_allclose(feet.min(axis=1), 0.0, atol=1e-6)
    assert np.all(p[:, :, 1] > -1e-6)
    assert np.all(p[:, i("Head"), 1] > p[:, i("Chest"), 1]) and np.all(p[:, i("Chest"), 1] > p[:, i("Hips"), 1])
    assert np.all(p[:, i("Toes_L"), 2] > p[:, i("Foot_L"), 2])  # faces +Z
    assert np.all(p[:, i("UpperArm_L"), 0] > p[:, i("UpperArm_R"), 0])  # its left is +X
    # legs nearly still, with some motion
    knee = p[:, i("LowerLeg_L")]
    assert 0.05 < np.ptp(knee, axis=0).max() < 12.0
    # hands never inside the torso: keep out of a 9 cm cylinder around the spine above the hips
    for h in ("Hand_L", "Hand_R"):
        d = p[:, i(h)] - p[:, i("Spine")]
        above = p[:, i(h), 1] > p[:, i("Hips"), 1]
        assert np.all(np.hypot(d[above, 0], d[above, 2]) > 9.0)


def test_styles_differ_as_their_parameters_say(fk):
    spec = _short("argument", 8.0)
    speed = {}
    for s in ("energetic", "neutral", "sad"):
        hl, hr = _hands(render_clip(spec, s, seed=0)[0], fk)
        speed[s] = _speed(hl).mean() + _speed(hr).mean()
    assert speed["energetic"] > speed["neutral"] > speed["sad"]
    # hand height raises the mean hand height
    base = STYLES["neutral"]
    heights = [
        np.mean(_hands(render_clip(spec, dataclasses.replace(base, hand_height=h), seed=0)[0], fk)[1][:, 1])
        for h in (-10.0, 0.0, 10.0)
    ]
    assert heights[0] < heights[1] < heights[2]
    # lean: the head is further forward of the hips when sad than neutral than proud
    fwd = {}
    for s in ("sad", "neutral", "proud"):
        m = render_clip(spec, s, seed=0)[0]
        p = fk(m)
        fwd[s] = np.mean(p[:, m.skeleton.index("Head"), 2] - p[:, m.skeleton.index("Hips"), 2])
    assert fwd["sad"] > fwd["neutral"] > fwd["proud"]


def test_tempo_changes_stroke_timing(fk):
    spec = dataclasses.replace(_short("directions", 8.0), strokes=(("point", 1.0),))
    active = []
    for tempo in (0.6, 1.0, 1.8):
        style = dataclasses.replace(STYLES["neutral"], tempo=tempo, smoothness=0.0, sway=0.0)
        m = render_clip(spec, style, seed=0)[0]
        hr = _hands(m, fk)[1]
        disp = np.linalg.norm(hr - hr[0], axis=-1)
        active.append(np.mean(disp > 0.5 * disp.max()))
    assert active[0] > active[1] > active[2]


def test_handedness_tremor_smoothness(fk):
    spec = dataclasses.replace(_short("directions", 8.0), strokes=(("point", 1.0), ("wave", 1.0)))
    right = _hands(render_clip(spec, "neutral", seed=0)[0], fk)
    left = _hands(render_clip(spec, "left_handed", seed=0)[0], fk)
    assert _speed(right[1]).mean() > 2 * _speed(right[0]).mean()
    assert _speed(left[0]).mean() > 2 * _speed(left[1]).mean()

    def jitter(style):
        hr = _hands(render_clip(spec, style, seed=0)[0], fk)[1]
        return np.abs(np.diff(hr, n=2, axis=0)).mean()

    base = STYLES["neutral"]
    assert jitter(dataclasses.replace(base, tremor=1.5)) > 2 * jitter(base)
    assert jitter(dataclasses.replace(base, smoothness=0.25)) < jitter(dataclasses.replace(base, smoothness=0.0))


def test_stroke_apexes_on_audio_onsets():
    librosa = pytest.importorskip("librosa")
    spec = CONTENTS["argument"].with_seed(2, 12.0)
    script = make_script(spec)
    _, audio, sr = render_clip(spec, "neutral", seed=0)
    onsets = librosa.onset.onset_detect(y=audio, sr=sr, units="time")
    apex = np.array([s.apex for s in script.strokes])
    assert len(apex) >= 4 and len(onsets) >= len(apex)

    def mean_dist(times):
        return np.mean(np.min(np.abs(times[:, None] - onsets[None, :]), axis=1))

    rng = np.random.default_rng(0)
    chance = np.mean([mean_dist(rng.uniform(0, spec.seconds, len(apex))) for _ in range(200)])
    assert mean_dist(apex) < 0.5 * chance
    assert mean_dist(apex) < 0.05  # within 50 ms


def test_hand_stops_only_at_stop_keys():
    from jaxgest.motion.synthetic.strokes import interpolate_hand_keys, interpolate_keys

    t = np.linspace(0.0, 2.0, 2001)
    times, values = [0.0, 1.0, 2.0], np.array([[0.0], [1.0], [3.0]])
    via = interpolate_keys(times, values, t, stops=[True, False, True])[:, 0]
    every = interpolate_keys(times, values, t)[:, 0]
    v_via, v_every = np.gradient(via, t), np.gradient(every, t)
    mid = 1000  # t = 1: a via key is passed through, a stop key is a full stop
    assert abs(v_every[mid]) < 1e-3 and v_via[mid] > 1.0
    assert abs(v_via[0]) < 1e-3 and abs(v_via[-1]) < 1e-3
    assert np.all(v_via[1:-1] > 0)  # one movement: no interior speed minimum at zero
    np.testing.assert_allclose(via[[0, -1]], [0.0, 3.0])
    # the hand version follows the same timing along an arc and keeps the keys' end points
    hand = interpolate_hand_keys(times, np.array([[20.0, 0, 0], [0, 20.0, 0], [-20.0, 0, 0]]), t,
                                 stops=[True, False, True])
    np.testing.assert_allclose(np.linalg.norm(hand, axis=-1), 20.0, atol=1e-9)
    assert np.linalg.norm(np.gradient(hand, t, axis=0)[mid]) > 1.0


def test_timeline_keeps_its_start_pose_and_fast_preparations():
    from jaxgest.motion.synthetic.strokes import APEX, STOP, VIA, _add_keys, leave_lead

    rest = np.zeros(3)
    stroke = [(0.05, np.ones(3)), (0.4, 2 * np.ones(3)), (0.6, 2 * np.ones(3)), (1.0, rest)]
    kinds = [VIA, APEX, VIA, STOP]
    keys = [(0.0, rest, STOP)]
    _add_keys(keys, stroke, kinds, rest, leave_lead(1.0))  # a preparation 50 ms into the clip
    assert keys[0][0] == 0.0 and keys[0][2] == STOP  # the start pose stays
    assert [k[0] for k in keys] == sorted(k[0] for k in keys)
    # a very fast tempo: the leave key must not swallow the preparation key
    keys = [(0.0, rest, STOP)]
    prep_at = 2.0
    _add_keys(keys, [(prep_at, np.ones(3)), (prep_at + 0.1, 2 * np.ones(3)), (prep_at + 0.3, rest)],
              [VIA, APEX, STOP], rest, leave_lead(4.0))
    assert any(t == prep_at and kind == VIA for t, _, kind in keys), keys


def test_kinematic_beats_of_clean_motion_align_with_speech_onsets(fk):
    """The data property the ZeroEGGS beat-alignment criterion relies on: in every style, the speed minima
    of the captured (clean) motion sit on speech onsets more than on shifted onsets (BeatAlign > control)."""
    pytest.importorskip("librosa")
    from jaxgest import metrics

    aligned, control = [], []
    for content in ("argument", "directions", "story"):
        spec = CONTENTS[content].with_seed(0, 10.0)
        for style in STYLES:
            m, audio, sr = render_clip(spec, style, seed=0)
            hl, hr = _hands(m, fk)
            speed = metrics.hand_speed(np.stack([hl, hr], 1), FPS, [0, 1])
            beats = metrics.kinematic_beats(speed, FPS)
            onsets = metrics.onset_times(audio, sr)
            aligned.append(metrics.beat_alignment(beats, onsets))
            control.append(metrics.shuffled_beat_alignment(beats, onsets, spec.seconds, seed=0))
    aligned, control = np.array(aligned), np.array(control)
    assert aligned.mean() > control.mean() + 0.08, (aligned.mean(), control.mean())
    assert np.mean(aligned > control) >= 0.8, np.round(aligned - control, 3)


def test_custom_spec_and_style_validation():
    with pytest.raises(ValueError):
        StyleParams("x", handedness="both")
    with pytest.raises(KeyError, match="unknown synthetic style"):
        syn.get_style("nope")
    spec = ContentSpec("custom", seconds=2.5, seed=5, strokes=(("beat", 1.0),))
    m, _, _ = render_clip(spec, "neutral")
    assert m.num_frames == 150


def test_write_dataset(tmp_path):
    import soundfile as sf

    from jaxgest.motion import bvh

    manifest = syn.write_dataset(tmp_path / "d", clips=3, seed=1, seconds=2.5, progress=False)
    with open(manifest, newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0].keys()) == ["path", "content", "style", "audio"]
    assert len(rows) == 3 and len({r["style"] for r in rows}) == 3 and len({r["content"] for r in rows}) == 1
    for r in rows:
        assert r["path"] == f"{r['content']}_{r['style']}_0.bvh"
        m = bvh.load(tmp_path / "d" / r["path"])
        assert m.num_frames == 150 and abs(m.fps - 60.0) < 1e-6
        y, sr = sf.read(tmp_path / "d" / r["audio"])
        assert sr == 16000 and len(y) == 40000
    ref, _, _ = render_clip(CONTENTS[rows[0]["content"]].with_seed(1, 2.5), rows[0]["style"], seed=1000)
    m = bvh.load(tmp_path / "d" / rows[0]["path"])
    dots = np.abs(np.sum(m.rotations * ref.rotations, axis=-1))
    assert np.degrees(2 * np.arccos(np.clip(dots, 0, 1))).max() < 1e-3
    np.testing.assert_allclose(m.translations, ref.translations, atol=1e-4)
    plan = syn.dataset.clip_plan(None)
    assert len(plan) == len(CONTENTS) * len(STYLES)
    assert syn.dataset.clip_plan(len(plan) + 1)[-1][2] == 1

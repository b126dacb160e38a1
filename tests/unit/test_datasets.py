"""Folder datasets (Bandai-Namco, ZEGGS, manifest), windows, normalisation stats, resampling."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.runtime.errors import CheckpointError, DataError
from jaxgest.motion import datasets as ds
from jaxgest.motion.synthetic import CONTENTS, render_clip


@pytest.fixture(scope="module")
def motion():
    return render_clip(CONTENTS["story"].with_seed(0, 2.0), "neutral", seed=0)[0]


def test_bandai_layout(bandai_dir):
    assert ds.detect_layout(bandai_dir) == "bandai"
    clips = ds.load_folder(bandai_dir)
    assert len(clips) == 174
    assert len({c.style for c in clips}) == 15
    assert {"not-confident", "normal", "proud"} <= {c.style for c in clips}
    assert {"walk-back", "dance-short", "bow"} <= {c.content for c in clips}
    assert all(c.audio is None for c in clips)


def test_zeggs_layout(zeggs_dir):
    clips = ds.load_folder(zeggs_dir)
    assert len(clips) == 1
    c = clips[0]
    assert c.style == "Speech" and c.content == "067_Speech_2_x_1_0" and c.audio.name == "067_Speech_2_x_1_0.wav"
    assert c.motion.num_frames == 2065 and abs(c.motion.fps - 30.0) < 1e-3 and c.audio_start == 0.0


def test_zeggs_raw_file_trimmed_by_info_csv(tmp_path, motion):
    from jaxgest.motion import bvh

    bvh.save(motion, tmp_path / "001_Neutral_0.bvh")  # 120 frames at 60 fps
    (tmp_path / "info.csv").write_text(
        "audio_filename,audio_start_time,anim_start_time,acting_start_time,acting_end_time,anim_bvh\n"
        "001_Neutral_0.wav,09:00:00:00,09:00:00:30,09:00:00:40,09:00:01:30 ,001_Neutral_0.bvh\n"
    )
    (c,) = ds.load_folder(tmp_path)
    assert c.style == "Neutral" and c.audio is None
    assert c.motion.num_frames == 50  # acting 40..90 (1/60 s) minus the animation start 30
    np.testing.assert_allclose(c.motion.translations, motion.translations[10:60], atol=1e-4)
    assert c.audio_start == pytest.approx(40 / 60)


def test_manifest_and_errors(tmp_path, motion):
    from jaxgest.motion import bvh

    with pytest.raises(DataError, match="not a directory"):
        ds.load_folder(tmp_path / "nope")
    with pytest.raises(DataError, match="no .bvh"):
        ds.load_folder(tmp_path)
    bvh.save(motion, tmp_path / "a.bvh")
    with pytest.raises(DataError, match="unknown dataset layout.*a.bvh"):
        ds.load_folder(tmp_path)
    (tmp_path / "manifest.csv").write_text("path,content,style\na.bvh,story,neutral\n")
    (c,) = ds.load_folder(tmp_path)
    assert (c.content, c.style, c.audio) == ("story", "neutral", None)
    (tmp_path / "manifest.csv").write_text("path,content,style\nb.bvh,story,neutral\n")
    with pytest.raises(DataError, match="b.bvh does not exist"):
        ds.load_folder(tmp_path)
    (tmp_path / "manifest.csv").write_text("path,style\na.bvh,neutral\n")
    with pytest.raises(DataError, match="missing column"):
        ds.load_folder(tmp_path)
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "dataset-1_bow_sad_001.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    with pytest.raises(bvh.BVHError):
        ds.load_folder(bad)


def test_sample_windows(motion):
    rng = np.random.default_rng(0)
    arrays = [np.arange(30.0).reshape(10, 3), np.arange(60.0).reshape(20, 3)]
    w = ds.sample_windows(arrays, 8, 16, rng)
    assert w.data.shape == (16, 8, 3)
    for i, s, x in zip(w.index, w.start, w.data):
        np.testing.assert_array_equal(x, arrays[i][s:s + 8])
    w = ds.sample_windows([motion], 30, 2, rng)
    assert [m.num_frames for m in w.data] == [30, 30]
    with pytest.raises(DataError, match=r"25-frame window.*the longest, clip 1, has 20 frames.*clip 0"):
        ds.sample_windows(arrays, 25, 4, rng)


def test_norm_stats(tmp_path):
    import jax.numpy as jnp

    x = np.random.default_rng(0).normal(3.0, 2.0, size=(4, 50, 3))
    x[..., 2] = 1.0  # constant channel: std floored
    s = ds.NormStats.from_data(x)
    z = s.normalize(x)
    np.testing.assert_allclose(z[..., :2].reshape(-1, 2).mean(0), 0, atol=1e-9)
    np.testing.assert_allclose(z[..., :2].reshape(-1, 2).std(0), 1, atol=1e-9)
    assert s.std[2] == s.eps
    s.save(tmp_path / "stats.json")
    s2 = ds.NormStats.load(tmp_path / "stats.json")
    np.testing.assert_array_equal(s2.mean, s.mean)
    np.testing.assert_array_equal(s2.std, s.std)
    zj = s2.normalize(jnp.asarray(x, jnp.float32))
    assert zj.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(s2.denormalize(zj)), x, atol=1e-4)
    with pytest.raises(CheckpointError):
        ds.NormStats.load(tmp_path / "missing.json")


@settings(max_examples=10, deadline=None)
@given(st.sampled_from([30.0, 50.0, 120.0]))
def test_resample_motion(motion, fps):
    from jaxgest.motion.rotations import quat_angle, quat_inv, quat_mul

    r = ds.resample_motion(motion, fps)
    assert r.fps == fps and r.num_frames == int(np.floor((motion.num_frames - 1) * fps / 60 + 1e-9)) + 1
    np.testing.assert_allclose(np.linalg.norm(r.rotations, axis=-1), 1.0, atol=1e-9)
    if fps in (30.0, 120.0):  # frames that coincide with source frames are copied
        k = int(60 / 30) if fps == 30.0 else 1
        src = motion.rotations[::k] if fps == 30.0 else motion.rotations
        dst = r.rotations if fps == 30.0 else r.rotations[::2]
        assert np.max(quat_angle(quat_mul(quat_inv(src), dst))) < 1e-6
    back = ds.resample_motion(ds.resample_motion(motion, 120.0), 60.0)
    np.testing.assert_allclose(back.translations, motion.translations, atol=1e-9)


def test_dataset_repository_root_uses_its_data_folder(bandai_dir, tmp_path):
    root = tmp_path / "bandai-namco-1"
    (root / "data").mkdir(parents=True)
    (root / "README.md").write_text("the dataset repository's own files\n")
    for p in sorted(bandai_dir.glob("dataset-1_bow_*.bvh"))[:2]:
        (root / "data" / p.name).symlink_to(p)
    clips = ds.load_folder(root)
    assert len(clips) == 2 and clips[0].content == "bow"
    with pytest.raises(DataError, match="no .bvh files"):
        ds.load_folder(tmp_path / "bandai-namco-1" / "..")  # a folder with neither clips nor data/


def test_fit_frames_cuts_or_holds_the_last_frame(motion):
    cut = ds.fit_frames(motion, 5)
    np.testing.assert_array_equal(cut.rotations, motion.rotations[:5])
    longer = ds.fit_frames(motion, motion.num_frames + 3)
    assert longer.num_frames == motion.num_frames + 3
    np.testing.assert_array_equal(longer.translations[-3:], np.repeat(motion.translations[-1:], 3, 0))
    i0, i1, w = ds.resample_weights(4, 30.0, 60.0, 7)
    np.testing.assert_array_equal(i0, [0, 0, 1, 1, 2, 2, 3])
    np.testing.assert_allclose(w, [0, 0.5, 0, 0.5, 0, 0.5, 0])

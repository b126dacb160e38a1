"""ZeroEGGS data: speech features, aligned sequences, augmentation, deterministic batches."""

from __future__ import annotations

import types

import numpy as np
import pytest
import soundfile as sf
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.audio import FEATURE_DIM, FeatureStats, load_audio, speech_features
from jaxgest.runtime.errors import AudioError, DataError
from jaxgest.motion.synthetic import write_dataset
from jaxgest.zeggs import data as zdata


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("zsyn")
    write_dataset(out, clips=3, seconds=5, progress=False)
    return out


def test_speech_features_shapes_and_degenerate_audio(tmp_path):
    sr = 16000
    t = np.arange(sr * 2) / sr
    y = (0.3 * np.sin(2 * np.pi * 220 * t)).astype(np.float32)
    f = speech_features(y, sr=sr, fps=60)
    assert f.shape == (120, FEATURE_DIM) and np.all(np.isfinite(f))
    for degenerate in (np.zeros(sr), np.full(sr, 0.5), np.zeros(10)):
        g = speech_features(degenerate, sr=sr, fps=30)
        assert np.all(np.isfinite(g)) and g.shape[1] == FEATURE_DIM
    # any rate / channels / container: stereo 44.1 kHz FLAC gives the same frame count
    stereo = np.stack([np.sin(2 * np.pi * 220 * np.arange(44100 * 2) / 44100)] * 2, axis=1) * 0.3
    sf.write(tmp_path / "s.flac", stereo, 44100)
    assert speech_features(tmp_path / "s.flac", fps=60).shape == (120, FEATURE_DIM)
    y2, sr2 = load_audio(tmp_path / "s.flac", sr=16000)
    assert sr2 == 16000 and y2.ndim == 1 and abs(len(y2) - 32000) <= 1


def test_bad_audio_is_a_clear_error(tmp_path):
    with pytest.raises(AudioError, match="NaN"):
        speech_features(np.array([0.0, np.nan, 0.1]), sr=16000)
    with pytest.raises(AudioError, match="empty"):
        speech_features(np.zeros(0), sr=16000)
    (tmp_path / "bad.wav").write_bytes(b"RIFF0000WAVEnope")
    with pytest.raises(AudioError, match="bad.wav: unreadable"):
        speech_features(tmp_path / "bad.wav")
    with pytest.raises(AudioError, match="no such audio"):
        speech_features(tmp_path / "none.wav")
    sf.write(tmp_path / "empty.wav", np.zeros(0), 16000)
    with pytest.raises(AudioError, match="empty"):
        speech_features(tmp_path / "empty.wav")


def test_feature_stats_round_trip(tmp_path):
    x = np.random.default_rng(0).normal(size=(50, FEATURE_DIM))
    st = FeatureStats.fit([x[:20], x[20:]])
    np.testing.assert_allclose(st.normalise(x).mean(0), 0, atol=1e-5)
    st.save(tmp_path / "s.json")
    np.testing.assert_allclose(FeatureStats.load(tmp_path / "s.json").mean, st.mean)


def test_sequences_and_batches(synth_dir):
    data = zdata.load(synth_dir, fps=60, speeds=(0.9, 1.0, 1.1))
    assert len(data.sequences) == 3 * 2 * 3  # clips x (original, mirrored) x speeds
    lengths = {round(s.frames / 10) for s in data.sequences if s.name.endswith("@1")}
    fast = [s for s in data.sequences if s.name.endswith("@1.1")]
    assert all(s.frames < 300 for s in fast) and lengths
    kw = dict(seed=3, batch=4, window=64, style_min=64, style_max=128)
    b = data.batch(5, **kw)
    assert b["pose"].shape == (4, 64, data.pose_dim) and b["speech"].shape == (4, 64, 81)
    assert b["style"].shape == (4, 128, data.pose_dim) and b["style_mask"].dtype == bool
    assert np.all(b["style_mask"].sum(1) >= 64)
    np.testing.assert_allclose(b["root_position"][:, 0], 0, atol=1e-5)  # windows start at their own origin
    np.testing.assert_allclose(np.linalg.norm(b["facing"], axis=-1), 1, atol=1e-5)
    again = data.batch(5, **kw)
    assert all(np.array_equal(b[k], again[k]) for k in b)
    other = data.batch(6, **kw)
    assert not np.array_equal(b["pose"], other["pose"])
    with pytest.raises(DataError, match="no clip is long enough"):
        data.batch(0, seed=0, batch=2, window=10_000, style_min=64, style_max=128)


def _seqs(lengths, styles, clips, mirrored=None, speeds=None):
    mirrored = mirrored or [False] * len(lengths)
    speeds = speeds or [1.0] * len(lengths)
    return [types.SimpleNamespace(frames=n, style=s, clip=c, mirrored=mi, speed=v)
            for n, s, c, mi, v in zip(lengths, styles, clips, mirrored, speeds)]


@settings(max_examples=60, deadline=None)
@given(frames=st.integers(40, 400), window=st.integers(4, 64), smin=st.integers(4, 64), extra=st.integers(0, 64),
       seed=st.integers(0, 2**31 - 1))
def test_style_window_modes(frames, window, smin, extra, seed):
    smax = smin + extra
    rng = np.random.default_rng(seed)
    # y.bvh is x.bvh's same-style other clip; its mirror (index 3) and its sped-up copy (index 4) are other
    # variants and never chosen
    seqs = _seqs([frames, frames + 7, 300, frames + 7, frames + 7], ["a", "a", "b", "a", "a"],
                 ["x.bvh", "y.bvh", "z.bvh", "y.bvh", "y.bvh"], [False, False, False, True, False],
                 [1.0, 1.0, 1.0, 1.0, 1.1])
    if frames >= window + smin:  # disjoint: the target lies outside the style window
        t0, (j, s0, m) = zdata.style_window(seqs, 0, rng, window=window, style_min=smin, style_max=smax,
                                        sampling="disjoint")
        assert j == 0 and 0 <= t0 <= frames - window and smin <= m <= smax and 0 <= s0 <= frames - m
        assert s0 + m <= t0 or s0 >= t0 + window
    if frames >= max(window, smin):  # overlap (the paper): the style window contains the target
        t0, (j, s0, m) = zdata.style_window(seqs, 0, rng, window=window, style_min=smin, style_max=smax,
                                        sampling="overlap")
        assert j == 0 and 0 <= s0 <= frames - m and m <= max(smax, window)
        assert (s0 <= t0 and t0 + window <= s0 + m) if m >= window else (t0 <= s0 and s0 + m <= t0 + window)
        # other-clip: another clip of the same style ("y.bvh"), never the target's own clip or another style
        t0, (j, s0, m) = zdata.style_window(seqs, 0, rng, window=window, style_min=smin, style_max=smax,
                                        sampling="other-clip")
        assert j == 1 and smin <= m <= min(smax, frames + 7) and 0 <= s0 <= frames + 7 - m
    # the only clip of its style: other-clip falls back to disjoint
    t0, (j, s0, m) = zdata.style_window(seqs, 2, rng, window=window, style_min=smin, style_max=smax,
                                    sampling="other-clip")
    assert j == 2 and (s0 + m <= t0 or s0 >= t0 + window)


def _find(norm, block):
    """Start frames ``u`` where ``norm[u:u + len(block)]`` equals ``block`` (first-row match, then the rest)."""
    n = len(block)
    cand = np.flatnonzero(np.abs(norm[:len(norm) - n + 1] - block[0]).max(axis=1) < 1e-5)
    return [int(u) for u in cand if np.abs(norm[u:u + n] - block).max() < 1e-5]


def test_batch_sampling_modes(synth_dir, tmp_path):
    bvhs = sorted(synth_dir.glob("*.bvh"))  # relabelled: two clips of style "a", one of style "b"
    (tmp_path / "manifest.csv").write_text("path,content,style,audio\n" + "".join(
        f"{p.resolve()},c{i},{'aab'[i]},{p.with_suffix('.wav').resolve()}\n" for i, p in enumerate(bvhs)))
    data = zdata.load(tmp_path, fps=60, speeds=(1.0,))
    norms = [data.pose_stats.normalize(s.pose) for s in data.sequences]
    kw = dict(seed=1, batch=6, window=64, style_min=64, style_max=96)
    for mode in zdata.SAMPLING_MODES:
        b = data.batch(2, sampling=mode, **kw)
        for r in range(6):  # locate the target and its style window among the sequences' frames
            target = b["pose"][r]
            style = b["style"][r, :int(b["style_mask"][r].sum())]
            own = [(i, u) for i in range(len(norms)) for u in _find(norms[i], target)]
            assert len(own) == 1
            i, t0 = own[0]
            s = data.sequences[i]
            hits = _find(norms[i], style)
            alone = mode == "other-clip" and s.style == "b"  # no other clip of its style: disjoint
            if mode == "overlap":
                assert any(u <= t0 and t0 + 64 <= u + len(style) for u in hits)
            elif mode == "disjoint" or alone:
                assert hits and all(u + len(style) <= t0 or u >= t0 + 64 for u in hits)
            else:  # another clip of the same style, the same variant (a mirror swaps the dominant hand)
                assert not hits
                src = [o for o, x in zip(data.sequences, norms) if o.clip != s.clip and _find(x, style)]
                assert src and all(o.style == s.style and o.mirrored == s.mirrored for o in src)
    with pytest.raises(DataError, match="unknown style sampling"):
        data.batch(0, sampling="nearby", **kw)
    with pytest.raises(DataError, match="disjoint"):  # 5 s clips: no room for 64 + 300 frames apart
        data.batch(0, seed=0, batch=2, window=64, style_min=300, style_max=300, sampling="disjoint")


def test_folder_without_audio_is_rejected(tmp_path, synth_dir):
    import shutil

    for f in synth_dir.glob("*.bvh"):
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "manifest.csv").write_text("path,content,style\n" + "".join(
        f"{f.name},c,s\n" for f in sorted(tmp_path.glob("*.bvh"))))
    with pytest.raises(DataError, match="no clip has audio"):
        zdata.load(tmp_path, fps=60)


@pytest.mark.realdata
def test_real_zeggs_sample_aligns(zeggs_dir):
    data = zdata.load(zeggs_dir, fps=30, speeds=(1.0,))
    s = data.sequences[0]
    assert data.pose_dim == 15 * 75 + 6 and s.frames == 2065  # 68.8 s at 30 fps, audio and motion agree

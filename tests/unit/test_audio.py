"""Speech features (jaxgest.audio): shapes at the motion rate, spectral content, robustness, clear errors.

Checks of values written for the ``"librosa"`` method (log energy, natural-log mel) name it; the ``"authors"``
method (the default) is checked against the authors' own code in tests/unit/test_authors_speech.py."""

from __future__ import annotations

import json

import librosa
import numpy as np
import pytest
import soundfile as sf

from jaxgest import audio
from jaxgest.runtime.errors import AudioError, CheckpointError

SR = 16000


def tone(freq=1000.0, seconds=1.0, sr=SR, amp=0.5):
    t = np.arange(int(seconds * sr)) / sr
    return (amp * np.sin(2 * np.pi * freq * t)).astype(np.float32)


def test_real_zeggs_wav(zeggs_dir):
    path = zeggs_dir / "067_Speech_2_x_1_0.wav"
    info = sf.info(str(path))
    feats = audio.speech_features(path, fps=60, method="librosa")
    assert feats.shape == (int(round(info.frames / info.samplerate * 60)), audio.FEATURE_DIM)
    assert feats.dtype == np.float32 and np.all(np.isfinite(feats))
    # Speech varies: energy spans a wide range and the log-mel channels are not constant.
    assert np.ptp(feats[:, -1]) > 5.0
    assert np.all(feats[:, :80].std(axis=0) > 0.1)
    # 30 fps gives half the frames of the same audio.
    assert audio.speech_features(path, fps=30, method="librosa").shape[0] == int(round(info.frames / info.samplerate * 30))


@pytest.mark.parametrize("method", audio.SPEECH_METHODS)
def test_tone_peaks_in_its_mel_band(method):
    feats = audio.speech_features(tone(1000.0), sr=SR, fps=60, method=method)
    assert feats.shape == (60, 81)
    centres = librosa.mel_frequencies(n_mels=audio.N_MELS + 2, fmin=audio.FMIN, fmax=audio.FMAX)[1:-1]
    band = int(np.argmax(feats[30, :80]))
    assert abs(centres[band] - 1000.0) < 80.0


def test_energy_follows_loudness():
    y = np.concatenate([tone(440, 0.5, amp=0.01), tone(440, 0.5, amp=0.5)])
    e = audio.speech_features(y, sr=SR, fps=60, method="librosa")[:, -1]
    # 34 dB louder -> log energy up by 2 * ln(50) ~ 7.8
    assert e[45] - e[15] == pytest.approx(2 * np.log(50.0), abs=0.3)


@pytest.mark.parametrize("y", [np.zeros(SR, np.float32), np.full(SR, 0.3, np.float32),
                               np.zeros(10, np.float32), np.ones(3, np.float32)], ids=["silence", "dc", "short", "tiny"])
@pytest.mark.parametrize("method", audio.SPEECH_METHODS)
def test_degenerate_audio_is_finite(y, method):
    feats = audio.speech_features(y, sr=SR, fps=60, method=method)
    assert feats.shape == (max(1, int(round(len(y) / SR * 60))), 81)
    assert np.all(np.isfinite(feats))


def test_flac_stereo_44k(tmp_path):
    mono = tone(300.0, 1.0, sr=44100)
    stereo = np.stack([mono, 0.5 * mono], axis=1)
    path = tmp_path / "speech.flac"
    sf.write(str(path), stereo, 44100, subtype="PCM_24")
    y, sr = audio.load_audio(path)
    assert sr == 44100 and y.ndim == 1 and len(y) == 44100
    np.testing.assert_allclose(y, 0.75 * mono, atol=1e-5)  # channels averaged (24-bit FLAC)
    y16, sr16 = audio.load_audio(path, sr=16000)
    assert sr16 == 16000 and len(y16) == 16000 and y16.dtype == np.float32
    from_file = audio.speech_features(path, fps=60, method="librosa")
    from_array = audio.speech_features(stereo, sr=44100, fps=60, method="librosa")
    assert from_file.shape == (60, 81)
    loud = from_array > np.log(audio.LOG_FLOOR) + 4  # quantisation noise only matters near the floor
    np.testing.assert_allclose(from_file[loud], from_array[loud], atol=0.05)
    # Resampled to 16 kHz first: the tone lands in the same band.
    assert np.argmax(audio.speech_features(path, sr=16000, method="librosa")[30, :80]) == np.argmax(from_file[30, :80])


def test_k_weighting_matches_the_bs1770_table_at_48k():
    (b1, a1), (b2, a2) = audio.k_weighting(48000)
    np.testing.assert_allclose(b1, [1.53512485958697, -2.69169618940638, 1.19839281085285], atol=1e-10)
    np.testing.assert_allclose(a1, [1.0, -1.69065929318241, 0.73248077421585], atol=1e-10)
    np.testing.assert_allclose(b2, [1.0, -2.0, 1.0])
    np.testing.assert_allclose(a2, [1.0, -1.99004745483398, 0.99007225036621], atol=1e-10)


@pytest.mark.parametrize("sr", [16000, 48000])
def test_integrated_loudness_of_reference_signals(sr):
    # BS.1770: a 0 dB FS 997 Hz sine in one channel reads -3.01 LKFS (K-weighting gain ~ 0 dB near 1 kHz).
    assert audio.integrated_loudness(tone(997.0, 2.0, sr=sr, amp=1.0), sr) == pytest.approx(-3.01, abs=0.05)
    # Any full-scale sine: -0.691 + 10 log10(1/2) + the K-weighting gain at its frequency, the gain taken
    # from the recommendation's 48 kHz coefficients (at 16 kHz the bilinear warping moves it < 0.15 dB).
    from scipy.signal import freqz

    table = ([1.53512485958697, -2.69169618940638, 1.19839281085285], [1.0, -1.69065929318241, 0.73248077421585]), \
        ([1.0, -2.0, 1.0], [1.0, -1.99004745483398, 0.99007225036621])
    for f in (100.0, 4000.0):
        gain = np.prod([abs(freqz(b, a, [f], fs=48000)[1][0]) for b, a in table])
        expected = -0.691 + 10 * np.log10(0.5) + 20 * np.log10(gain)
        got = audio.integrated_loudness(tone(f, 2.0, sr=sr, amp=1.0), sr)
        assert got == pytest.approx(expected, abs=0.02 if sr == 48000 else 0.15), f
    # Gating: 1 s of tone then 3 s of near-silence (-80 dB, under the absolute gate). Kept: the 7 blocks of
    # 400 ms inside the tone and the 3 straddling its end (3/4, 1/2, 1/4 of the tone's energy, all above the
    # relative gate): mean energy 8.5 / 10 of the tone's. Without gating it would read ~6 dB lower.
    alone = audio.integrated_loudness(tone(997.0, 1.0, sr=sr, amp=0.1), sr)
    y = np.concatenate([tone(997.0, 1.0, sr=sr, amp=0.1), tone(997.0, 3.0, sr=sr, amp=1e-4)])
    assert audio.integrated_loudness(y, sr) == pytest.approx(alone + 10 * np.log10(0.85), abs=0.02)
    assert audio.integrated_loudness(np.zeros(sr, np.float32), sr) == -np.inf


def test_loudness_normalisation():
    y = tone(500.0)
    z = audio.normalize_loudness(y, SR)
    assert audio.integrated_loudness(z, SR) == pytest.approx(audio.LOUDNESS_LUFS, abs=1e-3)
    np.testing.assert_array_equal(audio.normalize_loudness(np.zeros(100, np.float32), SR), 0.0)
    # On by default: features do not depend on the recording level; off, they do (20 dB: energy + 2 ln 10).
    a = audio.speech_features(y, sr=SR, method="librosa")
    b = audio.speech_features(0.1 * y, sr=SR, method="librosa")
    np.testing.assert_allclose(a, b, atol=1e-3)
    raw_a = audio.speech_features(y, sr=SR, loudness=False, method="librosa")
    raw_b = audio.speech_features(0.1 * y, sr=SR, loudness=False, method="librosa")
    assert np.median(raw_a[:, -1] - raw_b[:, -1]) == pytest.approx(2 * np.log(10.0), abs=0.05)  # log energy


def test_errors_name_the_file(tmp_path):
    bad = tmp_path / "garbage.wav"
    bad.write_bytes(b"not a wav file at all")
    with pytest.raises(AudioError, match="garbage.wav"):
        audio.speech_features(bad)
    with pytest.raises(AudioError, match="missing.wav"):
        audio.load_audio(tmp_path / "missing.wav")
    nan = tmp_path / "nan.wav"
    y = tone()
    y[100] = np.nan
    sf.write(str(nan), y, SR, subtype="FLOAT")
    with pytest.raises(AudioError, match="nan.wav.*NaN"):
        audio.speech_features(nan)
    empty = tmp_path / "empty.wav"
    sf.write(str(empty), np.zeros(0, np.float32), SR)
    with pytest.raises(AudioError, match="empty.wav.*empty"):
        audio.load_audio(empty)
    with pytest.raises(AudioError, match="inf"):
        audio.speech_features(np.array([0.0, np.inf], np.float32), sr=SR)
    with pytest.raises(AudioError, match="empty"):
        audio.speech_features(np.zeros(0, np.float32), sr=SR)
    with pytest.raises(AudioError, match="sample rate"):
        audio.speech_features(y)


def test_feature_stats_roundtrip(tmp_path):
    rng = np.random.default_rng(0)
    feats = [rng.normal(3.0, 2.0, (50, 81)), rng.normal(3.0, 2.0, (70, 81))]
    feats[0][:, 5] = 1.0  # constant channel: std floored, no division by zero
    feats[1][:, 5] = 1.0
    stats = audio.FeatureStats.fit(feats)
    z = stats.normalise(np.concatenate(feats))
    assert np.all(np.isfinite(z))
    np.testing.assert_allclose(z.mean(0), 0.0, atol=1e-5)
    np.testing.assert_allclose(np.delete(z.std(0), 5), 1.0, atol=1e-4)
    np.testing.assert_allclose(stats.denormalise(z), np.concatenate(feats), atol=1e-4)
    for name in ("speech_stats.json", "speech_stats.npz"):
        stats.save(tmp_path / name)
        back = audio.FeatureStats.load(tmp_path / name)
        np.testing.assert_array_equal(back.mean, stats.mean)
        np.testing.assert_array_equal(back.std, stats.std)
    assert set(json.loads((tmp_path / "speech_stats.json").read_text())) == {"mean", "std"}
    (tmp_path / "broken.json").write_text('{"mean": [1, 2]}')
    with pytest.raises(CheckpointError, match="broken.json"):
        audio.FeatureStats.load(tmp_path / "broken.json")

"""Speech features for ZeroEGGS: log-mel (80 bands) + frame energy at the motion frame rate.

``speech_features(wav_path_or_array, sr=None, fps=60) -> (F, 81)``: librosa mel spectrogram (Hann window
50 ms, hop 12.5 ms, 80 bands, fmin 20 Hz, fmax 7600 Hz clipped to the Nyquist frequency), log amplitude,
plus the log energy of each frame, interpolated to the motion rate with ``F = round(duration * fps)``
frames. Files of any sample rate and channel count are read with soundfile and mixed down. Silent,
constant and very short audio give finite features (the logs are floored); NaN/inf samples, unreadable
files and empty audio raise :class:`~jaxgest.runtime.errors.AudioError` naming the file. By default the audio is
first loudness-normalised to -20 LUFS (ITU-R BS.1770 integrated loudness, K-weighted and gated, in
NumPy + scipy.signal, which librosa already depends on), as the authors' pipeline does with pyloudnorm;
audio below the -70 LUFS gate (silence) is left as it is.

References: Ghorbani et al. 2023, §3.1 and §4.1 (log-amplitude mel spectrogram, 80 channels, total frame
energy, FFT Hanning window of 50 ms, hop 12.5 ms, resampled to the animation rate, normalised); docs/design.md §4
(the authors' code: fmin 20 Hz, fmax 7600 Hz, pyloudnorm to -20 LUFS); ITU-R BS.1770-4 (loudness).
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
from typing import Optional, Union

import numpy as np

from jaxgest.runtime.errors import AudioError, CheckpointError
from jaxgest.runtime.io import write_text_atomic

N_MELS = 80
FEATURE_DIM = N_MELS + 1
WINDOW_S = 0.050
HOP_S = 0.0125
FMIN = 20.0
FMAX = 7600.0
LOG_FLOOR = 1e-5
LOUDNESS_LUFS = -20.0  # integrated loudness of loudness-normalised speech (ITU-R BS.1770, as the authors)


def load_audio(path, sr: Optional[int] = None) -> tuple[np.ndarray, int]:
    """Read WAV/FLAC/... as float32 mono (channels averaged), resampled to ``sr`` when given."""
    import soundfile as sf

    path = pathlib.Path(path)
    if not path.is_file():
        raise AudioError(f"{path}: no such audio file")
    try:
        y, file_sr = sf.read(str(path), dtype="float32", always_2d=True)
    except Exception as e:  # soundfile raises RuntimeError / LibsndfileError subclasses
        raise AudioError(f"{path}: unreadable audio ({str(e).splitlines()[0][:120]})") from None
    y = y.mean(axis=1)
    _check_samples(y, str(path))
    if sr is not None and int(sr) != int(file_sr):
        import librosa

        y = librosa.resample(y, orig_sr=file_sr, target_sr=int(sr)).astype(np.float32)
        file_sr = int(sr)
    return y.astype(np.float32), int(file_sr)


def _check_samples(y: np.ndarray, name: str) -> None:
    if y.size == 0:
        raise AudioError(f"{name}: empty audio (no samples)")
    if not np.all(np.isfinite(y)):
        raise AudioError(f"{name}: audio contains NaN or inf samples")


def k_weighting(sr: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The two K-weighting biquads ``[(b, a), (b, a)]`` (a[0] = 1) for sample rate ``sr``.

    Stage 1 is a high shelf (+4 dB above ~1.7 kHz, the head's acoustic effect), stage 2 the RLB
    high-pass (~38 Hz). Both are designed for any rate from their analogue prototypes by the bilinear
    transform (the constants of Brecht De Man's derivation, also used by pyloudnorm); at 48 kHz they equal
    the coefficients tabulated in the recommendation. References: ITU-R BS.1770-4, §2.1, Tables 1-2.
    """
    def shelf(gain_db, q, fc):
        k = np.tan(np.pi * fc / sr)
        vh = 10.0 ** (gain_db / 20.0)
        vb = vh ** 0.4996667741545416
        a0 = 1.0 + k / q + k * k
        return (np.array([(vh + vb * k / q + k * k), 2.0 * (k * k - vh), (vh - vb * k / q + k * k)]) / a0,
                np.array([1.0, 2.0 * (k * k - 1.0) / a0, (1.0 - k / q + k * k) / a0]))

    def high_pass(q, fc):
        k = np.tan(np.pi * fc / sr)
        a0 = 1.0 + k / q + k * k
        return np.array([1.0, -2.0, 1.0]), np.array([1.0, 2.0 * (k * k - 1.0) / a0, (1.0 - k / q + k * k) / a0])

    return [shelf(3.999843853973347, 0.7071752369554196, 1681.974450955533),
            high_pass(0.5003270373238773, 38.13547087602444)]


def integrated_loudness(y: np.ndarray, sr: float) -> float:
    """Gated integrated loudness of mono samples in LUFS (-inf for silence).

    K-weighting, mean squares over 400 ms blocks every 100 ms (one block of the whole signal when it is
    shorter), an absolute gate at -70 LUFS and a relative gate 10 LU below the loudness of the blocks above
    it. References: ITU-R BS.1770-4, §2 (eqs. 1-7); the authors' pipeline uses pyloudnorm, which
    implements the same recommendation.
    """
    from scipy.signal import lfilter  # scipy comes with librosa

    x = np.asarray(y, np.float64)
    for b, a in k_weighting(sr):
        x = lfilter(b, a, x)
    block, step = int(round(0.4 * sr)), int(round(0.1 * sr))
    if len(x) <= block:
        z = np.array([np.mean(x ** 2)]) if len(x) else np.zeros(1)
    else:
        starts = np.arange(0, len(x) - block + 1, step)
        c = np.concatenate([[0.0], np.cumsum(x ** 2)])
        z = (c[starts + block] - c[starts]) / block

    def lufs(ms):
        return -0.691 + 10.0 * np.log10(ms) if ms > 0 else -np.inf

    with np.errstate(divide="ignore"):
        loud = -0.691 + 10.0 * np.log10(np.maximum(z, 1e-300))
    kept = z[loud >= -70.0]
    if kept.size == 0:
        return -np.inf
    kept = z[(loud >= -70.0) & (loud >= lufs(kept.mean()) - 10.0)]
    return float(lufs(kept.mean()))


def normalize_loudness(y: np.ndarray, sr: float, target_lufs: float = LOUDNESS_LUFS) -> np.ndarray:
    """Scale samples so their integrated loudness (:func:`integrated_loudness`) is ``target_lufs``.

    Audio whose loudness is below the absolute gate (silence, DC, near-silence) is returned unchanged, so
    its features stay finite. The authors' data pipeline normalises every recording to -20 LUFS before
    feature extraction. References: ITU-R BS.1770-4; docs/design.md §4.
    """
    y = np.asarray(y, np.float32)
    loud = integrated_loudness(y, sr) if y.size else -np.inf
    if not np.isfinite(loud):
        return y
    return (y * 10.0 ** ((target_lufs - loud) / 20.0)).astype(np.float32)


def log_mel_energy(y: np.ndarray, sr: int) -> tuple[np.ndarray, float]:
    """Log-mel + log-energy frames ``(T, 81)`` at the STFT hop, and the hop in seconds."""
    import librosa

    n_fft = int(round(WINDOW_S * sr))
    hop = max(1, int(round(HOP_S * sr)))
    fmax = min(FMAX, sr / 2.0)
    if len(y) < n_fft:  # very short audio: pad so one frame exists
        y = np.pad(y, (0, n_fft - len(y)))
    spec = np.abs(librosa.stft(y, n_fft=n_fft, hop_length=hop, win_length=n_fft, window="hann", center=True))
    mel_basis = librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=N_MELS, fmin=min(FMIN, fmax / 2), fmax=fmax)
    mel = mel_basis @ spec  # amplitude mel spectrogram
    log_mel = np.log(np.maximum(mel, LOG_FLOOR))
    energy = np.log(np.maximum(np.sum(spec ** 2, axis=0) / n_fft, LOG_FLOOR ** 2))
    return np.concatenate([log_mel, energy[None]], axis=0).T.astype(np.float32), hop / sr


def speech_features(wav_path_or_array: Union[str, pathlib.Path, np.ndarray], sr: Optional[int] = None,
                    fps: float = 60.0, *, loudness: bool = True) -> np.ndarray:
    """Speech features ``(F, 81)`` at ``fps`` frames per second (``F = round(duration * fps)``, >= 1).

    ``wav_path_or_array``: a path (``sr`` then optionally resamples) or a 1-D/2-D sample array (``sr``
    required; 2-D arrays are ``(samples, channels)`` and mixed down). ``loudness=True`` (default, as the
    authors' pipeline) first scales the audio to :data:`LOUDNESS_LUFS` (:func:`normalize_loudness`);
    ``loudness=False`` uses the samples as they are.
    References: Ghorbani et al. 2023, §3.1, §4.1.
    """
    if isinstance(wav_path_or_array, (str, pathlib.Path)):
        y, sr = load_audio(wav_path_or_array, sr)
        name = str(wav_path_or_array)
    else:
        if sr is None:
            raise AudioError("speech_features: a sample array needs its sample rate (sr=...)")
        y = np.asarray(wav_path_or_array, np.float32)
        if y.ndim == 2:
            y = y.mean(axis=1)
        name = "audio array"
        _check_samples(y, name)
    if fps <= 0:
        raise AudioError(f"{name}: frame rate must be positive, got {fps}")
    if loudness:
        y = normalize_loudness(y, int(sr))
    feats, hop_s = log_mel_energy(y, int(sr))
    duration = len(y) / float(sr)
    frames = max(1, int(round(duration * fps)))
    # Linear interpolation from STFT frame times (k * hop) to motion frame times (f / fps).
    src_t = np.arange(feats.shape[0]) * hop_s
    dst_t = np.arange(frames) / float(fps)
    out = np.empty((frames, FEATURE_DIM), np.float32)
    for c in range(FEATURE_DIM):
        out[:, c] = np.interp(dst_t, src_t, feats[:, c])
    return out


@dataclasses.dataclass(frozen=True)
class FeatureStats:
    """Per-channel mean/std of speech features, saved beside a model (``speech_stats.json``)."""

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, features, eps: float = 1e-3) -> "FeatureStats":
        x = np.concatenate([np.asarray(f, np.float64).reshape(-1, FEATURE_DIM) for f in features], axis=0) \
            if isinstance(features, (list, tuple)) else np.asarray(features, np.float64).reshape(-1, FEATURE_DIM)
        return cls(x.mean(axis=0), np.maximum(x.std(axis=0), eps))

    def normalise(self, x: np.ndarray) -> np.ndarray:
        return ((np.asarray(x) - self.mean) / self.std).astype(np.float32)

    def denormalise(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x) * self.std + self.mean).astype(np.float32)

    def save(self, path) -> None:
        """JSON (any suffix but ``.npz``) or NumPy ``.npz`` with arrays ``mean`` and ``std``."""
        path = pathlib.Path(path)
        if path.suffix == ".npz":
            from jaxgest.runtime.io import atomic_output

            with atomic_output(path) as tmp:
                with open(tmp, "wb") as f:  # a file object: np.savez would append ".npz" to a name
                    np.savez(f, mean=self.mean, std=self.std)
            return
        write_text_atomic(path, json.dumps({"mean": self.mean.tolist(), "std": self.std.tolist()}) + "\n")

    @classmethod
    def load(cls, path) -> "FeatureStats":
        path = pathlib.Path(path)
        try:
            if path.suffix == ".npz":
                with np.load(path) as d:
                    mean, std = np.asarray(d["mean"]), np.asarray(d["std"])
            else:
                d = json.loads(path.read_text())
                mean, std = np.asarray(d["mean"]), np.asarray(d["std"])
            if mean.shape != (FEATURE_DIM,) or std.shape != (FEATURE_DIM,) or not np.all(std > 0):
                raise ValueError(f"expected mean/std of shape ({FEATURE_DIM},) with std > 0")
            return cls(mean, std)
        except (OSError, ValueError, KeyError) as e:
            raise CheckpointError(f"{path}: missing or unreadable speech statistics ({e})") from None

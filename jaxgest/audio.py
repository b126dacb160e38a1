"""Speech features for ZeroEGGS: 80 log-mel bands + frame energy at the motion frame rate.

``speech_features(wav_path_or_array, sr=None, fps=60, method="authors") -> (F, 81)``, ``F = round(duration *
fps)`` (>= 1), by one of two methods (:data:`SPEECH_METHODS`):

* ``"authors"`` (the default, and the default of new ZeroEGGS models: ``ModelConfig.speech_features``): the
  ZeroEGGS authors' pipeline (their ``data_pipeline.preprocess_audio`` with ``data_pipeline_conf.json``),
  re-implemented in NumPy/SciPy/librosa and checked against their code (tests/unit/test_authors_speech.py):
  audio at 16 kHz (other rates resampled with libsoxr "HQ", the library behind their SoX ``rate -h``),
  loudness-normalised to -20 LUFS with pyloudnorm's meter (:func:`integrated_loudness` ``meter="pyloudnorm"``),
  an 800-sample symmetric-Hann STFT every 200 samples (reflect-padded, amplitudes / 800), Slaney mel
  filterbank (80 bands, 20-7600 Hz, area-normalised), amplitudes clipped at 1e-5 / 800, mapped to dB and the
  dB range to [0, 1] (``normalize_range``), then ``log(10 ** (x / 20))``; energy = the Euclidean norm over
  bands of ``exp`` of that; both linearly interpolated to the motion frames. The released speech encoders
  (:mod:`jaxgest.zeggs.torch_import`) expect exactly these features.
* ``"librosa"`` (models trained before the authors' method existed: their ``config.json`` has no
  ``speech_features`` field and keeps this one): librosa mel spectrogram (periodic Hann window 50 ms, hop
  12.5 ms at the file's rate, 80 bands, 20 Hz - min(7600 Hz, Nyquist)), natural log of the amplitude floored
  at 1e-5, plus the log of the frame's mean power, interpolated to the motion rate; loudness normalisation
  with the ITU-R BS.1770 K-weighting (:func:`integrated_loudness` ``meter="bs1770"``).

Files of any sample rate and channel count are read with soundfile and mixed down. Silent, constant and very
short audio give finite features (audio below the -70 LUFS gate is left at its level; the logs are floored);
NaN/inf samples, unreadable files and empty audio raise :class:`~jaxgest.runtime.errors.AudioError` naming the
file.

References: Ghorbani et al. 2023, §3.1 and §4.1 (log-amplitude mel spectrogram, 80 channels, total frame
energy, FFT Hanning window of 50 ms, hop 12.5 ms, resampled to the animation rate, normalised); the authors'
code (ubisoft-laforge-ZeroEGGS 4992d9a: ``ZEGGS/data_pipeline.py`` ``preprocess_audio``,
``ZEGGS/audio/spectrograms.py``, ``data/processed_v1/data_pipeline_conf.json``); docs/design.md §4;
ITU-R BS.1770-4 (loudness); pyloudnorm 0.1.0-0.2.0 (Steinmetz & Reiss 2021, the authors' loudness meter; the same
integrated loudness in both).
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
SPEECH_METHODS = ("authors", "librosa")  # speech_features(method=...); see the module docstring
# The authors' audio_conf (data/processed_v1|v2/data_pipeline_conf.json, identical in both):
AUTHORS_SR = 16000  # sampling_rate
AUTHORS_N_FFT = 800  # filter_length (50 ms)
AUTHORS_HOP = 200  # hop_length (12.5 ms)
AUTHORS_MIN_AMPLITUDE = 1e-5  # min_clipping, divided by filter_length (real_amplitude)
LOUDNESS_METERS = ("bs1770", "pyloudnorm")  # integrated_loudness(meter=...)


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


def k_weighting(sr: float, design: str = "bs1770") -> list[tuple[np.ndarray, np.ndarray]]:
    """The two K-weighting biquads ``[(b, a), (b, a)]`` (a[0] = 1) for sample rate ``sr``.

    Stage 1 is a high shelf (+4 dB above ~1.7 kHz, the head's acoustic effect), stage 2 the RLB
    high-pass (~38 Hz). ``design="bs1770"``: both designed for any rate from their analogue prototypes by
    the bilinear transform with the constants of Brecht De Man's derivation (pyloudnorm's optional "DeMan"
    filters); at 48 kHz they equal the coefficients tabulated in the recommendation.
    ``design="pyloudnorm"``: pyloudnorm's default "K-weighting" (what the ZeroEGGS authors measured with), RBJ
    cookbook biquads with a +4 dB shelf at 1500 Hz (Q 1/sqrt 2) and a 38 Hz high-pass (Q 0.5); they only
    approximate the table (at 16 kHz speech reads ~0.12 LU quieter than with ``"bs1770"``).
    References: ITU-R BS.1770-4, §2.1, Tables 1-2; R. Bristow-Johnson, Audio EQ Cookbook (high shelf, high
    pass); pyloudnorm ``IIRfilter``.
    """
    if design == "pyloudnorm":
        def rbj(kind, gain_db, q, fc):
            a_ = 10.0 ** (gain_db / 40.0)
            w0 = 2.0 * np.pi * (fc / sr)
            alpha = np.sin(w0) / (2.0 * q)
            c, r = np.cos(w0), 2.0 * np.sqrt(a_) * alpha
            if kind == "shelf":
                b = [a_ * ((a_ + 1) + (a_ - 1) * c + r), -2 * a_ * ((a_ - 1) + (a_ + 1) * c),
                     a_ * ((a_ + 1) + (a_ - 1) * c - r)]
                a = [(a_ + 1) - (a_ - 1) * c + r, 2 * ((a_ - 1) - (a_ + 1) * c), (a_ + 1) - (a_ - 1) * c - r]
            else:
                b = [(1 + c) / 2, -(1 + c), (1 + c) / 2]
                a = [1 + alpha, -2 * c, 1 - alpha]
            return np.array(b) / a[0], np.array(a) / a[0]

        return [rbj("shelf", 4.0, 1 / np.sqrt(2), 1500.0), rbj("high_pass", 0.0, 0.5, 38.0)]
    if design != "bs1770":
        raise ValueError(f"K-weighting design must be one of {LOUDNESS_METERS}, got {design!r}")
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


def integrated_loudness(y: np.ndarray, sr: float, meter: str = "bs1770") -> float:
    """Gated integrated loudness of mono samples in LUFS (-inf for silence).

    K-weighting, mean squares over 400 ms blocks every 100 ms (one block of the whole signal when it is
    shorter), an absolute gate at -70 LUFS and a relative gate 10 LU below the loudness of the blocks above
    it. ``meter="bs1770"``: the recommendation's filters, blocks while a whole block fits, float64
    throughout. ``meter="pyloudnorm"``: pyloudnorm's ``Meter(sr).integrated_loudness`` as the ZeroEGGS
    authors call it, step for step (its RBJ K-weighting, each filter's output stored in the input's dtype,
    ``round((T - 0.4) / 0.1) + 1`` blocks with truncated sample bounds, the last one possibly short but
    divided by the full block length, strict gates), equal to it to ~1e-12 LU; audio shorter than a block,
    which pyloudnorm refuses, is measured as one block. References: ITU-R BS.1770-4, §2 (eqs. 1-7);
    pyloudnorm ``Meter.integrated_loudness``.
    """
    from scipy.signal import lfilter  # scipy comes with librosa

    if meter == "pyloudnorm":
        return _pyloudnorm_loudness(np.asarray(y), sr)
    x = np.asarray(y, np.float64)
    for b, a in k_weighting(sr, meter):
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


def _pyloudnorm_loudness(y: np.ndarray, sr: float) -> float:
    """:func:`integrated_loudness` with ``meter="pyloudnorm"`` (mono)."""
    from scipy.signal import lfilter

    if not np.issubdtype(y.dtype, np.floating):
        y = y.astype(np.float64)
    x = y.reshape(-1).copy()
    for b, a in k_weighting(sr, "pyloudnorm"):
        x[:] = lfilter(b, a, x)  # stored back in the input's dtype, as pyloudnorm does
    t_g, step = 0.4, 1.0 - 0.75
    if len(x) < t_g * sr:
        z = np.array([np.mean(np.square(x.astype(np.float64)))])
    else:
        n = int(np.round(((len(x) / sr - t_g) / (t_g * step)))) + 1
        blocks = ((int(t_g * (j * step) * sr), int(t_g * (j * step + 1) * sr)) for j in range(n))
        z = np.array([(1.0 / (t_g * sr)) * np.sum(np.square(x[lo:hi])) for lo, hi in blocks], np.float64)
    with np.errstate(divide="ignore"):
        loud = -0.691 + 10.0 * np.log10(z)
        above = loud >= -70.0
        if not above.any():
            return -np.inf
        gamma_r = -0.691 + 10.0 * np.log10(np.mean(z[above])) - 10.0
        kept = (loud > gamma_r) & (loud > -70.0)
        return float(-0.691 + 10.0 * np.log10(np.mean(z[kept]))) if kept.any() else -np.inf


def normalize_loudness(y: np.ndarray, sr: float, target_lufs: float = LOUDNESS_LUFS,
                       meter: str = "bs1770") -> np.ndarray:
    """Scale samples so their integrated loudness (:func:`integrated_loudness` with ``meter``) is
    ``target_lufs``.

    Audio whose loudness is below the absolute gate (silence, DC, near-silence) is returned unchanged, so
    its features stay finite (pyloudnorm's ``normalize.loudness`` would scale it by an infinite gain into
    NaN). The authors' data pipeline normalises every recording to -20 LUFS before feature extraction.
    ``meter="bs1770"`` returns float32; ``meter="pyloudnorm"`` multiplies the samples, as given, by the
    float64 gain, as pyloudnorm does (float32 samples become float64). References: ITU-R BS.1770-4;
    pyloudnorm ``normalize.loudness``; docs/design.md §4.
    """
    if meter == "pyloudnorm":
        y = np.asarray(y)
        loud = integrated_loudness(y, sr, meter) if y.size else -np.inf
        return y if not np.isfinite(loud) else np.power(10.0, (target_lufs - loud) / 20.0) * y
    y = np.asarray(y, np.float32)
    loud = integrated_loudness(y, sr, meter) if y.size else -np.inf
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


def resample_soxr(y: np.ndarray, sr: int, target_sr: int) -> np.ndarray:
    """Resample mono samples from ``sr`` to ``target_sr`` with libsoxr at its "HQ" quality (20-bit, linear
    phase), the resampler behind SoX's ``rate -h`` that the authors' ``read_wavfile`` calls for a WAV not at
    16 kHz. Through SoX (its own build of the library and a 32-bit integer WAV in between) the samples differ
    by up to ~6e-5 of full scale, which moves the authors' features by up to ~1e-5 (measured from 22.05, 44.1
    and 48 kHz; tests/unit/test_authors_speech.py).
    References: the authors' ``ZEGGS/audio/audio_files.py`` (``read_wavfile``, ``reformat_and_trim_wav_file``).
    """
    if int(sr) == int(target_sr):
        return y
    import soxr  # a dependency of librosa (its default resampler)

    return soxr.resample(np.asarray(y, np.float32), int(sr), int(target_sr), quality="HQ").astype(np.float32)


def authors_mel_energy(y: np.ndarray, sr: int = AUTHORS_SR) -> tuple[np.ndarray, np.ndarray, float]:
    """The authors' log-mel frames ``(T, 80)``, energy ``(T,)`` (float64, at the STFT hop) and the hop (s).

    ``y``: loudness-normalised samples at ``sr`` (the authors' 16 kHz). Their ``extract_mel_spectrogram_for_tts``
    with ``data_pipeline_conf.json``'s options, operation for operation (so that rounding agrees too):

    * audio shorter than the window is zero-padded to it, then reflect-padded by half a window each side
      (``centered``); frames of 800 samples (:data:`AUTHORS_N_FFT`) every 200 (:data:`AUTHORS_HOP`), as many
      as ``floor((L - 800) / 200)``, plus one when ``L`` is not a multiple of 200 (their count, which drops
      the last whole frame otherwise);
    * symmetric Hann window, magnitude of the real FFT divided by 800 (``real_amplitude``);
    * Slaney mel filterbank, 80 bands from 20 to 7600 Hz, each band's area normalised (``normalize_mel_bins``;
      librosa's ``filters.mel``, which their code reproduces bit for bit);
    * amplitudes clipped at ``1e-5 / 800``, ``x = 20 log10(A)``, the range mapped by ``(x + R) / R`` with
      ``R = -20 log10(1e-5 / 800)`` (~158 dB; ``normalize_range``), then ``log(10 ** (x / 20))``: so each
      band is ``ln(10) / 20 * (1 + 20 log10(A) / R)``, a compressed log amplitude;
    * energy: the Euclidean norm over the bands of ``exp`` of that.

    References: the authors' ``ZEGGS/audio/spectrograms.py`` and ``ZEGGS/data_pipeline.py``
    (``preprocess_audio``, ``extract_energy``); Slaney, Auditory Toolbox (mel scale).
    """
    import librosa
    from scipy.signal.windows import hann

    n_fft, hop = AUTHORS_N_FFT, AUTHORS_HOP
    x = np.asarray(y)  # float32 stays float32 until the window (as theirs: float64 after pyloudnorm's gain)
    if not np.issubdtype(x.dtype, np.floating):
        x = x.astype(np.float64)
    if len(x) < n_fft:
        x = np.pad(x, (0, n_fft - len(x)))
    x = np.pad(x, (n_fft // 2, n_fft // 2), mode="reflect")
    frames = (len(x) - n_fft) // hop + (0 if len(x) % hop == 0 else 1)
    windows = np.lib.stride_tricks.sliding_window_view(x, n_fft)[::hop][:frames]
    amp = np.abs(np.fft.rfft(windows * hann(n_fft), axis=1)).T / n_fft  # (n_fft // 2 + 1, T)
    basis = librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=N_MELS, fmin=FMIN, fmax=FMAX, norm="slaney",
                                htk=False, dtype=np.float64)
    mel = np.dot(basis, amp)
    floor = AUTHORS_MIN_AMPLITUDE / n_fft
    db = 20 * np.log10(np.clip(np.abs(mel), a_min=floor, a_max=None))
    dynamic_range = -20 * np.log10(floor)
    log_mel = np.log(10 ** (((db + dynamic_range) / dynamic_range).T / 20))  # (T, 80)
    energy = np.linalg.norm(np.exp(log_mel).T, axis=0)
    return log_mel, energy, hop / float(sr)


def _interp_frames(values: np.ndarray, src_step: float, frames: int, fps: float) -> np.ndarray:
    """Linear interpolation of frames at ``k * src_step`` seconds to ``frames`` frames at ``fps``,
    extrapolated linearly past the ends (the authors' ``interp1d(kind="linear", fill_value="extrapolate")``;
    their ``griddata(method="linear")`` for the mel bands is the same interpolation inside the range, and
    the motion frames of ``round(duration * fps)`` never leave it)."""
    from scipy.interpolate import interp1d

    if len(values) == 1:
        return np.repeat(values[:1], frames, axis=0)
    pos = ((1.0 / src_step) / fps) * np.arange(frames)  # in source frames, as the authors compute it
    return interp1d(np.arange(len(values)), values, kind="linear", axis=0, fill_value="extrapolate")(pos)


def speech_features(wav_path_or_array: Union[str, pathlib.Path, np.ndarray], sr: Optional[int] = None,
                    fps: float = 60.0, *, loudness: bool = True, method: str = "authors") -> np.ndarray:
    """Speech features ``(F, 81)`` float32 at ``fps`` frames per second (``F = round(duration * fps)``, >= 1).

    ``wav_path_or_array``: a path or a 1-D/2-D sample array (``sr`` required; 2-D arrays are ``(samples,
    channels)`` and mixed down). ``method``: ``"authors"`` (default) or ``"librosa"`` (module docstring).
    With ``"librosa"``, ``sr`` given with a path resamples the file to ``sr`` first; ``"authors"`` always
    analyses at 16 kHz (a path with another ``sr`` is an error). ``loudness=True`` (default, as the authors'
    pipeline) first scales the audio to :data:`LOUDNESS_LUFS` (:func:`normalize_loudness`, with pyloudnorm's
    meter for ``"authors"``); ``loudness=False`` uses the samples as they are.
    References: Ghorbani et al. 2023, §3.1, §4.1; the authors' ``preprocess_audio`` (module docstring).
    """
    if method not in SPEECH_METHODS:
        raise AudioError(f"speech_features: unknown method {method!r} (one of {', '.join(SPEECH_METHODS)})")
    if isinstance(wav_path_or_array, (str, pathlib.Path)):
        if method == "authors" and sr is not None and int(sr) != AUTHORS_SR:
            raise AudioError(f"{wav_path_or_array}: the authors' speech features are computed at {AUTHORS_SR} Hz, "
                             f"not sr={sr}")
        y, sr = load_audio(wav_path_or_array, None if method == "authors" else sr)
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
    if method == "authors":
        return _authors_features(y, int(sr), fps, loudness)
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


def _authors_features(y: np.ndarray, sr: int, fps: float, loudness: bool) -> np.ndarray:
    """``speech_features(method="authors")`` of mono float32 samples at ``sr``."""
    y = resample_soxr(y, sr, AUTHORS_SR)
    frames = max(1, int(round(fps * (len(y) / AUTHORS_SR))))
    if loudness:
        y = normalize_loudness(y, AUTHORS_SR, meter="pyloudnorm")
    log_mel, energy, hop_s = authors_mel_energy(y, AUTHORS_SR)
    mel = _interp_frames(log_mel, hop_s, frames, fps).astype(np.float32)
    energy = _interp_frames(energy, hop_s, frames, fps).astype(np.float32)
    return np.concatenate([mel, energy[:, None]], axis=1)


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

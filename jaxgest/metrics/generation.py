"""Objective metrics for speech-driven generation (ZeroEGGS) and style embeddings (docs/design.md §5).

Paper 001 evaluates with user studies only (naturalness, appropriateness, style portrayal, §5.3); its
"mismatched motion" (MM) control motivates :func:`shuffled_beat_alignment`. The objective stand-ins here are
standard metrics, each named after its origin:
  * style-embedding linear-probe accuracy (closed-form ridge classifier on held-out clips);
  * beat alignment of kinematic beats with speech onsets (BeatAlign, Li et al. 2021, AIST++);
  * Fréchet distance between Gaussian fits of feature sets (Heusel et al. 2017 FID; FGD, Yoon et al. 2020).

All functions are deterministic NumPy (float64); librosa only for onset detection.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from jaxgest.runtime.errors import AudioError, DataError

# --------------------------------------------------------------------------------------------------------
# Linear probe


def _embeddings(x, name: str) -> np.ndarray:
    x = np.asarray(x, np.float64)
    if x.ndim != 2 or len(x) == 0:
        raise DataError(f"{name}: expected embeddings (clips, dims), got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise DataError(f"{name}: contains NaN or inf")
    return x


def linear_probe_predict(train_emb, train_labels: Sequence, test_emb, *, l2: float = 1e-3, std_floor=1e-8) -> list:
    """Labels predicted for ``test_emb`` by a closed-form ridge classifier fitted on (train_emb, train_labels).

    train_emb: (N, D), test_emb: (T, D); labels: any hashables (style names), length N. Features are
    standardised with the training mean / std, the std floored at ``std_floor`` (a number or one per feature
    (D,): a feature that is constant in training up to rounding must not turn a small test deviation into
    thousands of units, :func:`jaxgest.zeggs.style_judge.group_std_floor`); the classifier is the ridge regression
    to one-hot targets W = (X^T X + l2 * N * I)^-1 X^T Y with an unpenalised bias (centred X, Y); the
    prediction is argmax over the training classes (ties -> the first in sorted label order). Deterministic;
    no iterative training. One fit predicts any number of test rows (:func:`linear_probe_accuracy` scores them).

    References: linear evaluation protocol of representation learning (e.g. Alain & Bengio 2016, linear
    probes); applied to ZeroEGGS style embeddings (Ghorbani et al. 2023, §5.2) per docs/design.md §5.
    """
    xtr = _embeddings(train_emb, "linear_probe: train_emb")
    xte = _embeddings(test_emb, "linear_probe: test_emb")
    if xtr.shape[1] != xte.shape[1]:
        raise DataError(f"linear_probe: train dims {xtr.shape[1]} != test dims {xte.shape[1]}")
    ytr = list(train_labels)
    if len(ytr) != len(xtr):
        raise DataError("linear_probe: number of labels differs from number of embeddings")
    if not l2 > 0:
        raise DataError(f"linear_probe: l2 must be > 0, got {l2}")
    classes = sorted(set(ytr), key=str)
    index = {c: k for k, c in enumerate(classes)}
    onehot = np.zeros((len(ytr), len(classes)))
    onehot[np.arange(len(ytr)), [index[c] for c in ytr]] = 1.0
    floor = np.broadcast_to(np.asarray(std_floor, np.float64), xtr.shape[1:])
    if not np.all(floor > 0):
        raise DataError("linear_probe: std_floor must be > 0")
    mu, sd = xtr.mean(axis=0), np.maximum(xtr.std(axis=0), floor)
    xs, ts = (xtr - mu) / sd, (xte - mu) / sd
    ymu = onehot.mean(axis=0)
    gram = xs.T @ xs + l2 * len(xs) * np.eye(xs.shape[1])
    w = np.linalg.solve(gram, xs.T @ (onehot - ymu))
    return [classes[k] for k in np.argmax(ts @ w + ymu, axis=1)]


def linear_probe_accuracy(
    train_emb, train_labels: Sequence, test_emb, test_labels: Sequence, *, l2: float = 1e-3, std_floor=1e-8
) -> float:
    """Accuracy of the closed-form ridge classifier of :func:`linear_probe_predict` fitted on
    (train_emb, train_labels), on the test set (test_emb, test_labels; lengths T). Test labels unseen in
    training count as errors.

    References: linear evaluation protocol of representation learning (e.g. Alain & Bengio 2016, linear
    probes); applied to ZeroEGGS style embeddings (Ghorbani et al. 2023, §5.2) per docs/design.md §5.
    """
    pred = linear_probe_predict(train_emb, train_labels, test_emb, l2=l2, std_floor=std_floor)
    yte = list(test_labels)
    if len(yte) != len(pred):
        raise DataError("linear_probe_accuracy: number of labels differs from number of embeddings")
    return float(np.mean([p == t for p, t in zip(pred, yte)]))


# --------------------------------------------------------------------------------------------------------
# Beat alignment


def onset_times(audio, sr: int) -> np.ndarray:
    """Speech onset times in seconds ``(K,)`` (sorted) by librosa's spectral-flux onset detector.

    audio: (samples,) mono waveform; sr: its sampling rate. Uses ``librosa.onset.onset_detect`` (hop 512,
    no backtracking) with librosa's default peak-picking windows in seconds (30 ms max / wait, 100 ms
    average), each at least one frame: at 16 kHz librosa's own defaults round to 0 frames and report every
    onset twice; at 22.05 kHz and above the parameters equal librosa's defaults.
    References: Böck & Widmer 2013 / librosa onset_detect (spectral flux onset strength + peak picking).
    """
    import librosa

    y = np.asarray(audio, np.float32)
    if y.ndim != 1 or y.size == 0:
        raise AudioError(f"onset_times: expected a non-empty mono waveform, got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise AudioError("onset_times: waveform contains NaN or inf samples")
    if not sr > 0:
        raise AudioError(f"onset_times: sampling rate must be > 0, got {sr}")
    hop = 512
    frames = lambda seconds: max(1, int(seconds * sr // hop))
    onsets = librosa.onset.onset_detect(
        y=y,
        sr=int(sr),
        hop_length=hop,
        units="time",
        backtrack=False,
        pre_max=frames(0.03),
        post_max=1,
        pre_avg=frames(0.10),
        post_avg=int(0.10 * sr // hop) + 1,
        wait=frames(0.03),
        delta=0.07,
    )
    return np.asarray(onsets, np.float64)


def hand_speed(world_positions, fps: float, hand_indices: Sequence[int]) -> np.ndarray:
    """Summed speed of the given hands per frame ``(F, J, 3) -> (F,)`` (units of positions per second).

    Backward differences (frame t: p_t - p_{t-1}), frame 0 repeats frame 1, so frame t sits at time t / fps.
    References: kinetic velocity of Li et al. 2021 (AIST++ BeatAlign), restricted to the hands.
    """
    p = np.asarray(world_positions, np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or len(p) < 2:
        raise DataError(f"hand_speed: expected world positions (frames >= 2, joints, 3), got {p.shape}")
    idx = np.asarray(hand_indices, np.int64)
    s = np.linalg.norm(p[1:, idx] - p[:-1, idx], axis=-1).sum(axis=-1) * float(fps)
    return np.concatenate([s[:1], s])


def gaussian_smooth(x, sigma_frames: float) -> np.ndarray:
    """Gaussian smoothing of a 1-D signal ``(F,) -> (F,)``, equal to ``scipy.ndimage.gaussian_filter1d``.

    Kernel exp(-t^2 / (2 sigma^2)) normalised to sum 1, truncated at 4 sigma (radius int(4 sigma + 0.5)),
    boundary mode "reflect" (d c b a | a b c d | d c b a), as scipy's defaults. sigma_frames <= 0 -> copy.
    References: the Gaussian filter G(., 5) on kinetic velocity in the BeatAlign code of Li et al. 2021.
    """
    x = np.asarray(x, np.float64).reshape(-1)
    if not sigma_frames > 0 or x.size == 0:
        return x.copy()
    radius = int(4.0 * float(sigma_frames) + 0.5)
    t = np.arange(-radius, radius + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (t / float(sigma_frames)) ** 2)
    kernel /= kernel.sum()
    # Reflect-pad (half-sample symmetric), repeating the reflection when the kernel is longer than the signal.
    idx = np.arange(-radius, x.size + radius)
    period = 2 * x.size
    idx = np.mod(idx, period)
    idx = np.where(idx >= x.size, period - 1 - idx, idx)
    return np.convolve(x[idx], kernel[::-1], mode="valid")


def kinematic_beats(hand_speed, fps: float, *, smooth_s: float = 5.0 / 60.0) -> np.ndarray:
    """Times in seconds ``(B,)`` of the kinematic beats: strict local minima of the smoothed hand speed.

    hand_speed: (F,) per-frame speed (:func:`hand_speed`), frame t at time t / fps. The speed is smoothed by
    a Gaussian of standard deviation ``smooth_s`` seconds (:func:`gaussian_smooth`, sigma = smooth_s * fps
    frames; default 5 frames at 60 fps as in the AIST++ BeatAlign code; 0 disables smoothing); frame t
    (1 <= t <= F-2) is a beat when s[t] < s[t-1] and s[t] < s[t+1] (scipy's argrelextrema with np.less,
    order 1). End frames are never beats.
    References: Li et al. 2021 (AI Choreographer / AIST++), "kinematic beats" as local minima of velocity.
    """
    s = np.asarray(hand_speed, np.float64).reshape(-1)
    if not np.all(np.isfinite(s)):
        raise DataError("kinematic_beats: hand speed contains NaN or inf")
    if not fps > 0:
        raise DataError(f"kinematic_beats: fps must be > 0, got {fps}")
    s = gaussian_smooth(s, float(smooth_s) * float(fps))
    t = np.nonzero((s[1:-1] < s[:-2]) & (s[1:-1] < s[2:]))[0] + 1
    return t / float(fps)


def beat_alignment(beats_s, onsets_s, *, sigma: float = 0.1) -> float:
    """BeatAlign = mean over kinematic beats b of exp(-min_o (b - o)^2 / (2 sigma^2)), in [0, 1].

    beats_s: (B,) kinematic beat times (:func:`kinematic_beats`), onsets_s: (K,) speech onset times
    (:func:`onset_times`), both in seconds; sigma in seconds (default 0.1). Higher is better; compare with
    :func:`shuffled_beat_alignment`. No onsets -> 0. No beats -> DataError (the mean is undefined).
    References: Li et al. 2021 (AI Choreographer), Beat Alignment Score; docs/design.md §5 (ZEGGS beat alignment).
    """
    b = np.asarray(beats_s, np.float64).reshape(-1)
    o = np.asarray(onsets_s, np.float64).reshape(-1)
    if not sigma > 0:
        raise DataError(f"beat_alignment: sigma must be > 0, got {sigma}")
    if b.size == 0:
        raise DataError("beat_alignment: the motion has no kinematic beat (hand speed has no local minimum)")
    if o.size == 0:
        return 0.0
    d2 = np.min((b[:, None] - o[None, :]) ** 2, axis=1)
    return float(np.mean(np.exp(-d2 / (2.0 * sigma**2))))


def shuffled_beat_alignment(
    beats_s, onsets_s, duration: float, *, seed: int, n: int = 20, sigma: float = 0.1
) -> float:
    """Chance-level BeatAlign: the mean over ``n`` circular shifts of the onsets by random offsets.

    beats_s: (B,), onsets_s: (K,) seconds; duration: clip length in seconds (> 0). Offsets are drawn
    uniformly in [0, duration) with ``np.random.default_rng(seed)``; shifted onsets are wrapped modulo the
    duration (their count and spacing are kept, their timing relative to the motion is destroyed). Compare
    with :func:`beat_alignment` of the true onsets. Deterministic for a given seed.
    References: the mismatched-motion (MM) control of Ghorbani et al. 2023, §5.3; Li et al. 2021 BeatAlign.
    """
    if not duration > 0:
        raise DataError(f"shuffled_beat_alignment: duration must be > 0, got {duration}")
    if n < 1:
        raise DataError(f"shuffled_beat_alignment: n must be >= 1, got {n}")
    onsets = np.asarray(onsets_s, np.float64).reshape(-1)
    offsets = np.random.default_rng(seed).uniform(0.0, float(duration), size=n)
    scores = [beat_alignment(beats_s, np.mod(onsets + off, duration), sigma=sigma) for off in offsets]
    return float(np.mean(scores))


# --------------------------------------------------------------------------------------------------------
# Fréchet distance


def _psd_sqrt(c: np.ndarray) -> np.ndarray:
    """Symmetric square root ``(D, D)`` of a symmetric PSD matrix by eigh (negative round-off eigenvalues -> 0).

    References: spectral theorem; replaces scipy.linalg.sqrtm in FID code (Heusel et al. 2017).
    """
    w, v = np.linalg.eigh((c + c.T) / 2.0)
    return (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T


def gaussian_statistics(features) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(D,)`` and unbiased covariance ``(D, D)`` (ddof = 1) of a feature set ``(N, D)``, N >= 2.

    References: Heusel et al. 2017 (FID: Gaussian fit of the feature distribution).
    """
    x = _embeddings(features, "frechet_distance: features")
    if len(x) < 2:
        raise DataError(f"frechet_distance: need at least 2 feature vectors, got {len(x)}")
    return x.mean(axis=0), np.cov(x, rowvar=False, ddof=1).reshape(x.shape[1], x.shape[1])


def frechet_distance_from_statistics(mu_a, cov_a, mu_b, cov_b) -> float:
    """||mu_a - mu_b||^2 + tr(C_a) + tr(C_b) - 2 tr((C_a C_b)^{1/2}).

    tr((C_a C_b)^{1/2}) = tr((S C_b S)^{1/2}) with S = C_a^{1/2}: C_a C_b is similar to the symmetric PSD
    S C_b S, so both square roots come from eigh -- no scipy, no complex round-off. Clipped at 0.
    References: Dowson & Landau 1982 (Fréchet distance of Gaussians); Heusel et al. 2017 (FID).
    """
    mu_a, mu_b = np.asarray(mu_a, np.float64), np.asarray(mu_b, np.float64)
    cov_a, cov_b = np.asarray(cov_a, np.float64), np.asarray(cov_b, np.float64)
    s = _psd_sqrt(cov_a)
    w = np.linalg.eigvalsh((s @ cov_b @ s + (s @ cov_b @ s).T) / 2.0)
    tr_sqrt = float(np.sum(np.sqrt(np.clip(w, 0.0, None))))
    d = float(np.sum((mu_a - mu_b) ** 2) + np.trace(cov_a) + np.trace(cov_b) - 2.0 * tr_sqrt)
    return max(d, 0.0)


def frechet_distance(feat_a, feat_b) -> float:
    """Fréchet distance between Gaussian fits of two feature sets ``(Na, D)`` and ``(Nb, D)``.

    Mean and unbiased covariance of each set (:func:`gaussian_statistics`), then
    :func:`frechet_distance_from_statistics`. Used for motion features of generated vs real clips.
    References: Heusel et al. 2017 (FID); Yoon et al. 2020 (FGD for gestures); docs/design.md §5.
    """
    mu_a, cov_a = gaussian_statistics(feat_a)
    mu_b, cov_b = gaussian_statistics(feat_b)
    if mu_a.shape != mu_b.shape:
        raise DataError(f"frechet_distance: feature dims differ ({mu_a.shape[0]} vs {mu_b.shape[0]})")
    return frechet_distance_from_statistics(mu_a, cov_a, mu_b, cov_b)

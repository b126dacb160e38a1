"""Tests of jaxgest.metrics: exact DTW (JAX vs NumPy vs fastdtw), content / style errors, generation metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.errors import AudioError, DataError
from jaxgest.metrics import (
    arm_velocities,
    beat_alignment,
    content_error,
    content_error_components,
    dtw,
    dtw_numpy,
    dtw_wavefront,
    frechet_distance,
    gaussian_smooth,
    hand_speed,
    hands_metres,
    kinematic_beats,
    linear_probe_accuracy,
    onset_times,
    path_distances,
    shuffled_beat_alignment,
    style_error,
    style_error_components,
    summarize_errors,
    window_for_fps,
    window_statistics,
)

SETTINGS = settings(max_examples=25, deadline=None)


def _walk(rng, n, c=3):
    return np.cumsum(rng.normal(size=(n, c)), axis=0)


def _check_path(path, n, m):
    assert path.dtype.kind == "i" and path.ndim == 2 and path.shape[1] == 2
    assert tuple(path[0]) == (0, 0) and tuple(path[-1]) == (n - 1, m - 1)
    steps = {tuple(s) for s in np.diff(path, axis=0)}
    assert steps <= {(1, 0), (0, 1), (1, 1)}
    assert max(n, m) <= len(path) <= n + m - 1


# ------------------------------------------------------------------------------------------------- DTW


@SETTINGS
@given(n=st.integers(1, 40), m=st.integers(1, 40), seed=st.integers(0, 2**31 - 1), walk=st.booleans())
def test_dtw_matches_numpy_reference(n, m, seed, walk):
    rng = np.random.default_rng(seed)
    a, b = (_walk(rng, n), _walk(rng, m)) if walk else (rng.normal(size=(n, 3)), rng.normal(size=(m, 3)))
    cost, path = dtw(a, b)
    ref_cost, ref_path = dtw_numpy(a, b)
    _check_path(path, n, m)
    np.testing.assert_allclose(cost, ref_cost, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(cost, path_distances(a, b, path).sum(), rtol=1e-12)
    np.testing.assert_array_equal(path, ref_path)


@SETTINGS
@given(n=st.integers(1, 30), m=st.integers(1, 30), seed=st.integers(0, 2**31 - 1))
def test_dtw_matches_reference_with_many_exact_ties(n, m, seed):
    rng = np.random.default_rng(seed)
    a, b = (rng.integers(0, 3, size=(k, 2)).astype(np.float64) for k in (n, m))
    cost, path = dtw(a, b)
    ref_cost, ref_path = dtw_numpy(a, b)
    np.testing.assert_allclose(cost, ref_cost, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(path, ref_path)


def test_dtw_golden_with_ties():
    # d = |a_i - b_j| = [[0, 2], [1, 1], [2, 0]]: two optimal paths of cost 1; ties prefer the diagonal step.
    a, b = np.array([0.0, 1.0, 2.0]), np.array([0.0, 2.0])
    for fn in (dtw, dtw_numpy):
        cost, path = fn(a, b)
        assert cost == 1.0
        np.testing.assert_array_equal(path, [[0, 0], [1, 0], [2, 1]])


def test_dtw_identity_is_zero_with_diagonal_path():
    a = _walk(np.random.default_rng(1), 57, 6)
    cost, path = dtw(a, a)
    assert cost == 0.0
    np.testing.assert_array_equal(path, np.stack([np.arange(57)] * 2, axis=1))


@SETTINGS
@given(n=st.integers(1, 30), m=st.integers(1, 30), seed=st.integers(0, 2**31 - 1))
def test_dtw_cost_is_symmetric(n, m, seed):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(n, 3)), rng.normal(size=(m, 3))
    np.testing.assert_allclose(dtw(a, b)[0], dtw(b, a)[0], rtol=1e-6)


def test_dtw_frame_repetition_costs_nothing():
    a = _walk(np.random.default_rng(2), 40)
    b = np.repeat(a, 3, axis=0)[2:]  # time-stretched copy (first frame kept once)
    cost, path = dtw(a, b)
    assert cost == pytest.approx(0.0, abs=1e-12)
    _check_path(path, len(a), len(b))


def test_dtw_wavefront_cost_and_padding_invariance():
    import jax.numpy as jnp

    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(20, 3)), rng.normal(size=(13, 3))
    ref, _ = dtw_numpy(a, b)
    for pad_a, pad_b in [(20, 13), (64, 64), (23, 40)]:
        pa = np.concatenate([a, rng.normal(size=(pad_a - 20, 3)) * 100])  # garbage padding
        pb = np.concatenate([b, rng.normal(size=(pad_b - 13, 3)) * 100])
        cost, pred = dtw_wavefront(jnp.asarray(pa, jnp.float32), jnp.asarray(pb, jnp.float32), 20, 13)
        assert pred.shape == (pad_a + pad_b - 1, pad_a)
        np.testing.assert_allclose(float(cost), ref, rtol=1e-5)


def test_dtw_wavefront_jit_equals_eager():
    import jax
    import jax.numpy as jnp

    rng = np.random.default_rng(18)
    a, b = (
        jnp.asarray(rng.normal(size=(9, 2)), jnp.float32),
        jnp.asarray(rng.normal(size=(6, 2)), jnp.float32),
    )
    cost, pred = dtw_wavefront(a, b, 4, 3)
    with jax.disable_jit():
        cost_e, pred_e = dtw_wavefront(a, b, 4, 3)
    np.testing.assert_allclose(float(cost), float(cost_e), rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(pred), np.asarray(pred_e))
    np.testing.assert_allclose(float(cost), dtw_numpy(np.asarray(a)[:4], np.asarray(b)[:3])[0], rtol=1e-5)


def test_dtw_lengths_in_one_bucket_share_a_compilation():
    rng = np.random.default_rng(4)
    dtw(rng.normal(size=(10, 3)), rng.normal(size=(12, 3)))
    before = dtw_wavefront._cache_size()
    dtw(rng.normal(size=(33, 3)), rng.normal(size=(60, 3)))
    dtw(rng.normal(size=(64, 3)), rng.normal(size=(1, 3)))
    assert dtw_wavefront._cache_size() == before


def test_dtw_buckets():
    from jaxgest.metrics.dtw import _bucket

    sizes = [_bucket(k) for k in range(1, 5000)]
    assert all(s >= k for k, s in zip(range(1, 5000), sizes))
    assert all(s <= max(k + 63, 1.5 * k) for k, s in zip(range(1, 5000), sizes))
    assert sorted(set(sizes)) == [64, 128, 192, 256, 384, 512, 768, 1024, 1536, 2048, 3072, 4096, 6144]


def test_dtw_longer_clip_against_reference():
    rng = np.random.default_rng(5)
    a, b = _walk(rng, 150, 6), _walk(rng, 131, 6)
    cost, path = dtw(a, b)
    ref_cost, ref_path = dtw_numpy(a, b)
    np.testing.assert_allclose(cost, ref_cost, rtol=1e-12)
    np.testing.assert_array_equal(path, ref_path)


def test_dtw_not_worse_than_fastdtw():
    fastdtw = pytest.importorskip("fastdtw")
    rng = np.random.default_rng(6)
    for n, m in [(90, 70), (120, 121), (5, 80)]:
        a, b = _walk(rng, n, 6), _walk(rng, m, 6)
        approx, approx_path = fastdtw.fastdtw(a, b, radius=1, dist=2)
        cost, _ = dtw(a, b)
        assert cost <= approx + 1e-9
        assert cost <= path_distances(a, b, np.asarray(approx_path)).sum() + 1e-9


def test_dtw_equals_fastdtw_with_full_radius():
    fastdtw = pytest.importorskip("fastdtw")
    rng = np.random.default_rng(7)
    for n, m in [(30, 25), (12, 40), (1, 9)]:
        a, b = _walk(rng, n, 6), _walk(rng, m, 6)
        exact, path = fastdtw.fastdtw(a, b, radius=max(n, m), dist=2)  # the window covers every cell
        cost, _ = dtw(a, b)
        assert cost == pytest.approx(exact, rel=1e-12)
        assert path_distances(a, b, np.asarray(path)).sum() == pytest.approx(cost, rel=1e-12)


@pytest.mark.parametrize(
    "a, b",
    [
        (np.zeros((0, 3)), np.zeros((4, 3))),
        (np.zeros((3, 3)), np.zeros((4, 2))),
        (np.full((3, 3), np.nan), np.zeros((4, 3))),
        (np.zeros((3, 3, 1)), np.zeros((4, 3))),
    ],
)
def test_dtw_bad_input_raises_data_error(a, b):
    with pytest.raises(DataError):
        dtw(a, b)


# ------------------------------------------------------------------------------------------ content error


@pytest.mark.parametrize(
    "values, expected",
    [
        ([3.0], (3.0, 3.0, 3.0)),
        ([1.0, 2.0, 3.0], (2.0, 3.0, 3.0)),  # ceil(0.75) = 1 component
        ([1.0, 2.0, 3.0, 4.0, 5.0], (3.0, 5.0, 4.5)),  # ceil(1.25) = 2 components
        ([4.0, 1.0, 3.0, 2.0, 8.0, 0.0, 5.0, 7.0], (3.75, 8.0, 7.5)),  # 2 components
    ],
)
def test_summarize_errors(values, expected):
    s = summarize_errors(values)
    assert (s["mean"], s["worst"], s["w25"]) == pytest.approx(expected)


def test_content_error_identity_and_time_warp_are_zero():
    a = _walk(np.random.default_rng(7), 50, 6) * 0.01
    for b in (a, np.repeat(a, 2, axis=0)):
        assert content_error(a, b) == {"mean": 0.0, "worst": 0.0, "w25": 0.0}


def test_content_error_matches_reference_alignment():
    rng = np.random.default_rng(8)
    a, b = _walk(rng, 45, 6), _walk(rng, 38, 6)
    _, path = dtw_numpy(a, b)
    comps = np.linalg.norm(a[path[:, 0]] - b[path[:, 1]], axis=1)
    np.testing.assert_allclose(content_error_components(a, b), comps, rtol=1e-9)
    got = content_error(a, b)
    k = math.ceil(len(comps) / 4)
    assert got["mean"] == pytest.approx(comps.mean())
    assert got["worst"] == pytest.approx(comps.max())
    assert got["w25"] == pytest.approx(np.sort(comps)[-k:].mean())


def test_content_error_static_offset_and_trim():
    rng = np.random.default_rng(9)
    a = np.tile(rng.normal(size=(1, 6)), (30, 1))
    off = np.array([0.3, 0.0, 0.4, 0.0, 0.0, 0.0])
    assert content_error(a, a + off)["mean"] == pytest.approx(0.5)
    x, y = _walk(rng, 40, 6), _walk(rng, 44, 6)
    assert content_error(x, y, trim=5) == content_error(x[5:-5], y[5:-5])
    with pytest.raises(DataError):
        content_error(x, y, trim=20)
    with pytest.raises(DataError):
        content_error(x[:, :3], y[:, :3])


# -------------------------------------------------------------------------------------------- style error


def test_window_for_fps():
    assert [window_for_fps(f) for f in (60, 30, 20, 25, 120, 24)] == [128, 64, 43, 53, 256, 51]
    assert window_for_fps(30, theta_at_60=64) == 32


@pytest.mark.parametrize(
    "frames, window, starts",
    [
        (300, 128, [0, 64, 128]),
        (256, 128, [0, 64, 128]),  # the last window ends exactly at the clip end
        (128, 128, [0]),
        (11, 5, [0, 2, 4, 6]),  # odd theta: hop floor(5 / 2) = 2
    ],
)
def test_window_statistics_windows(frames, window, starts):
    x = np.random.default_rng(10).normal(size=(frames, 4))
    mean, std = window_statistics(x, window)
    ref = np.array([x[s : s + window] for s in starts])
    np.testing.assert_allclose(mean, ref.mean(axis=1))
    np.testing.assert_allclose(std, ref.std(axis=1))  # population std


def _style_reference(x, s, theta, per_joint):
    """Loop-by-loop eqs. 15-16 (independent of the vectorised code)."""
    h = theta // 2
    wins = lambda v: [v[k * h : k * h + theta] for k in range((len(v) - theta) // h + 1)]

    def norm(d):
        return (
            sum(np.linalg.norm(d[i : i + 3]) for i in range(0, len(d), 3)) if per_joint else np.linalg.norm(d)
        )

    return np.array(
        [min(norm(xk.mean(0) - sj.mean(0)) + norm(xk.std(0) - sj.std(0)) for sj in wins(s)) for xk in wins(x)]
    )


@pytest.mark.parametrize("joint_dims", [None, 3])
def test_style_error_matches_loop_reference(joint_dims):
    rng = np.random.default_rng(11)
    x, s = rng.normal(size=(100, 6)), rng.normal(size=(77, 6)) * 2.0 + 0.5
    got = style_error_components(x, s, 20, joint_dims=joint_dims)
    np.testing.assert_allclose(got, _style_reference(x, s, 20, joint_dims == 3), rtol=1e-12)
    assert style_error(x, s, 20, joint_dims=joint_dims) == summarize_errors(got)


@SETTINGS
@given(
    fx=st.integers(16, 60),
    fs=st.integers(16, 60),
    window=st.integers(2, 16),
    seed=st.integers(0, 2**31 - 1),
    shift=st.floats(-5.0, 5.0),
)
def test_style_error_properties(fx, fs, window, seed, shift):
    rng = np.random.default_rng(seed)
    x, s = rng.normal(size=(fx, 6)), rng.normal(size=(fs, 6))
    assert style_error(x, x, window) == {"mean": 0.0, "worst": 0.0, "w25": 0.0}
    comps = style_error_components(x, s, window)
    assert np.all(comps >= 0.0)
    np.testing.assert_allclose(style_error_components(x + shift, s + shift, window), comps, atol=1e-9)
    # Minimum over the style clip's windows <= the error against any single one of its windows.
    h = window // 2
    for k in range((fs - window) // h + 1):
        assert np.all(comps <= style_error_components(x, s[k * h : k * h + window], window) + 1e-12)


def test_style_error_trim_and_errors():
    rng = np.random.default_rng(12)
    x, s = rng.normal(size=(80, 6)), rng.normal(size=(90, 6))
    assert style_error(x, s, 16, trim=10) == style_error(x[10:-10], s[10:-10], 16)
    with pytest.raises(DataError, match="shorter than one window"):
        style_error(x[:15], s, 16)
    with pytest.raises(DataError, match="shorter than one window"):
        style_error(x, s, 16, trim=35)
    with pytest.raises(DataError):
        style_error(x, s[:, :5], 16)
    with pytest.raises(DataError):
        style_error(x[:, :5], s[:, :5], 16, joint_dims=3)


def test_arm_velocities_and_hands_metres():
    frames, fps = 7, 30.0
    t = np.arange(frames, dtype=np.float64)[:, None, None]
    step = np.arange(15, dtype=np.float64).reshape(1, 5, 3)
    pos = 2.0 * t * step + 1.0  # joint j moves by 2 * step[j] per frame
    v = arm_velocities(pos, fps, [3, 1])
    assert v.shape == (frames, 6)
    np.testing.assert_allclose(v, np.tile(np.concatenate([step[0, 3], step[0, 1]]) * 2.0 * fps, (frames, 1)))
    wobble = pos + np.sin(t * step)  # non-constant velocity: backward differences, frame 0 = frame 1
    vw = arm_velocities(wobble, fps, [2])
    np.testing.assert_allclose(vw[1:], (wobble[1:, 2] - wobble[:-1, 2]) * fps)
    np.testing.assert_allclose(vw[0], vw[1])
    np.testing.assert_allclose(arm_velocities(pos, fps, [3, 1], scale=0.01), v * 0.01)
    hands = hands_metres(pos, [4, 2])
    assert hands.shape == (frames, 6)
    np.testing.assert_allclose(hands[:, :3], pos[:, 4] / 100.0)
    np.testing.assert_allclose(hands[:, 3:], pos[:, 2] / 100.0)
    with pytest.raises(DataError):
        hands_metres(pos, [1, 2, 3])


# --------------------------------------------------------------------------------------- generation metrics


def test_linear_probe_separable_and_deterministic():
    rng = np.random.default_rng(13)
    centres = rng.normal(size=(3, 8)) * 5.0
    names = ["happy", "sad", "old"]
    lab_tr = [names[i % 3] for i in range(60)]
    lab_te = [names[i % 3] for i in range(30)]
    xtr = np.array([centres[names.index(c)] for c in lab_tr]) + rng.normal(size=(60, 8)) * 0.3
    xte = np.array([centres[names.index(c)] for c in lab_te]) + rng.normal(size=(30, 8)) * 0.3
    assert linear_probe_accuracy(xtr, lab_tr, xte, lab_te) == 1.0
    # Standardisation makes the probe invariant to per-feature scales; an unseen test label counts as wrong.
    scale = np.exp(rng.normal(size=8))
    assert linear_probe_accuracy(xtr * scale, lab_tr, xte * scale, lab_te) == 1.0
    assert linear_probe_accuracy(xtr, lab_tr, xte[:4], ["angry"] + lab_te[1:4]) == 0.75
    noisy = rng.normal(size=(60, 8))
    first = linear_probe_accuracy(noisy, lab_tr, xte, lab_te)
    assert first == linear_probe_accuracy(noisy, lab_tr, xte, lab_te)
    with pytest.raises(DataError):
        linear_probe_accuracy(xtr, lab_tr[:-1], xte, lab_te)


def test_linear_probe_matches_sklearn_ridge_classifier():
    sklearn_linear = pytest.importorskip("sklearn.linear_model")
    rng = np.random.default_rng(14)
    xtr, xte = rng.normal(size=(40, 5)), rng.normal(size=(25, 5))
    ytr = rng.integers(0, 4, 40)
    yte = rng.integers(0, 4, 25)
    mu, sd = xtr.mean(0), xtr.std(0)
    clf = sklearn_linear.RidgeClassifier(alpha=0.5 * 40).fit((xtr - mu) / sd, ytr)
    expected = float(np.mean(clf.predict((xte - mu) / sd) == yte))
    assert linear_probe_accuracy(xtr, ytr, xte, yte, l2=0.5) == pytest.approx(expected)


def test_beat_alignment_values():
    fps = 60.0
    speed = 2.0 - np.cos(2 * np.pi * np.arange(240) / 60.0)  # minima at frames 60, 120, 180
    np.testing.assert_allclose(kinematic_beats(speed, fps), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(kinematic_beats(speed, fps, smooth_s=0.0), [1.0, 2.0, 3.0])
    beats = kinematic_beats(speed, fps)
    assert beat_alignment(beats, [1.0, 2.0, 3.0]) == pytest.approx(1.0)
    assert beat_alignment(beats, [1.1, 2.0, 3.0], sigma=0.1) == pytest.approx((math.exp(-0.5) + 2) / 3)
    assert beat_alignment(beats, [2.0], sigma=0.1) == pytest.approx((2 * math.exp(-50.0) + 1) / 3)
    assert beat_alignment(beats, []) == 0.0
    assert beat_alignment([0.5], [0.7], sigma=0.2) == pytest.approx(math.exp(-0.5))
    with pytest.raises(DataError, match="no kinematic beat"):
        beat_alignment(kinematic_beats(np.linspace(0, 1, 50), fps), [0.1])


def test_kinematic_beats_smoothing_removes_jitter():
    fps = 60.0
    t = np.arange(240)
    slow = 2.0 - np.cos(2 * np.pi * t / 60.0)
    jitter = slow + 0.05 * (-1.0) ** t  # a local minimum every other frame without smoothing
    assert len(kinematic_beats(jitter, fps, smooth_s=0.0)) > 50
    np.testing.assert_allclose(kinematic_beats(jitter, fps), [1.0, 2.0, 3.0])


@pytest.mark.parametrize("n,sigma", [(50, 1.5), (200, 5.0), (7, 3.0), (1, 2.0)])
def test_gaussian_smooth_matches_scipy(n, sigma):
    ndimage = pytest.importorskip("scipy.ndimage")
    x = np.random.default_rng(n).normal(size=n)
    np.testing.assert_allclose(gaussian_smooth(x, sigma), ndimage.gaussian_filter1d(x, sigma), atol=1e-12)
    np.testing.assert_array_equal(gaussian_smooth(x, 0.0), x)


def test_shuffled_beat_alignment():
    fps = 60.0
    speed = 2.0 - np.cos(2 * np.pi * np.arange(600) / 45.0)  # 0.75 s period
    beats = kinematic_beats(speed, fps)
    onsets = beats.copy()
    aligned = beat_alignment(beats, onsets, sigma=0.05)
    control = shuffled_beat_alignment(beats, onsets, 10.0, sigma=0.05, seed=3)
    assert aligned == pytest.approx(1.0)
    assert control < 0.8
    assert control == shuffled_beat_alignment(beats, onsets, 10.0, sigma=0.05, seed=3)
    assert control != shuffled_beat_alignment(beats, onsets, 10.0, sigma=0.05, seed=4)
    one = shuffled_beat_alignment(beats, onsets, 10.0, sigma=0.05, seed=3, n=1)
    off = np.random.default_rng(3).uniform(0.0, 10.0, size=1)[0]
    assert one == pytest.approx(beat_alignment(beats, np.mod(onsets + off, 10.0), sigma=0.05))
    with pytest.raises(DataError):
        shuffled_beat_alignment(beats, onsets, 0.0, seed=0)


def test_hand_speed():
    pos = np.zeros((5, 3, 3))
    pos[:, 1, 0] = np.arange(5) * 0.5  # 0.5 per frame along x
    pos[:, 2, 2] = np.arange(5) * 1.0
    np.testing.assert_allclose(hand_speed(pos, 10.0, [1, 2]), np.full(5, 15.0))


@pytest.mark.parametrize("sr", [16000, 22050])
def test_onset_times_finds_bursts(sr):
    times = np.array([0.5, 1.2, 2.0])
    y = np.zeros(int(2.6 * sr), np.float32)
    rng = np.random.default_rng(15)
    n = sr // 20
    for t in times:
        i = int(t * sr)
        y[i : i + n] = rng.normal(size=n) * np.exp(-np.arange(n) / (n / 4))
    found = onset_times(y, sr)
    assert len(found) == len(times)  # one onset per burst (librosa's defaults give two at 16 kHz)
    np.testing.assert_allclose(found, times, atol=0.04)
    with pytest.raises(AudioError):
        onset_times(np.array([np.nan, 0.0]), sr)


def test_frechet_distance_against_scipy_sqrtm():
    linalg = pytest.importorskip("scipy.linalg")
    rng = np.random.default_rng(16)
    a = rng.normal(size=(200, 6)) @ rng.normal(size=(6, 6))
    b = rng.normal(size=(150, 6)) @ rng.normal(size=(6, 6)) + 0.7
    mu_a, mu_b = a.mean(0), b.mean(0)
    ca, cb = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    covmean = np.real(linalg.sqrtm(ca @ cb))
    ref = np.sum((mu_a - mu_b) ** 2) + np.trace(ca) + np.trace(cb) - 2.0 * np.trace(covmean)
    np.testing.assert_allclose(frechet_distance(a, b), ref, rtol=1e-7)
    np.testing.assert_allclose(frechet_distance(b, a), ref, rtol=1e-7)


def test_frechet_distance_properties():
    rng = np.random.default_rng(17)
    a = rng.normal(size=(100, 4))
    assert frechet_distance(a, a) == pytest.approx(0.0, abs=1e-9)
    shift = np.array([1.0, -2.0, 0.0, 0.5])
    assert frechet_distance(a, a + shift) == pytest.approx(float(shift @ shift), rel=1e-9)
    assert frechet_distance(a[:3], a[3:6]) >= 0.0  # rank-deficient covariances are fine
    with pytest.raises(DataError):
        frechet_distance(a[:1], a)
    with pytest.raises(DataError):
        frechet_distance(a, a[:, :3])

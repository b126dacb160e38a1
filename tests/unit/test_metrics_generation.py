"""Tests of jaxgest.metrics.generation: linear probe, kinematic beats and BeatAlign, onsets, Fréchet distance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxgest.runtime.errors import AudioError, DataError
from jaxgest.metrics import (
    beat_alignment,
    frechet_distance,
    frechet_distance_from_statistics,
    gaussian_smooth,
    hand_speed,
    kinematic_beats,
    linear_probe_accuracy,
    linear_probe_predict,
    onset_times,
    shuffled_beat_alignment,
)

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
    # closed form for Gaussians with diagonal covariances: |mu_a - mu_b|^2 + sum (sqrt(var_a) - sqrt(var_b))^2,
    # also when covariances are singular (zero variances)
    va, vb = np.array([4.0, 1.0, 0.0, 9.0]), np.array([1.0, 1.0, 2.25, 0.0])
    mu_a, mu_b = np.array([0.0, 1.0, 2.0, 3.0]), np.array([1.0, 1.0, 0.0, 3.0])
    expected = float(np.sum((mu_a - mu_b) ** 2) + np.sum((np.sqrt(va) - np.sqrt(vb)) ** 2))  # 5 + 1 + 2.25 + 9
    assert frechet_distance_from_statistics(mu_a, np.diag(va), mu_b, np.diag(vb)) == pytest.approx(expected)
    assert expected == pytest.approx(17.25)
    # and from samples: two large Gaussian samples, means 3 apart in one dim, stds 1 and 2 in another
    rng2 = np.random.default_rng(18)
    x = rng2.normal(size=(200_000, 2))
    y = rng2.normal(size=(200_000, 2)) * [1.0, 2.0] + [3.0, 0.0]
    assert frechet_distance(x, y) == pytest.approx(9.0 + 1.0, rel=0.01)
    with pytest.raises(DataError):
        frechet_distance(a[:1], a)
    with pytest.raises(DataError):
        frechet_distance(a, a[:, :3])


def test_linear_probe_std_floor():
    """A feature constant in training up to rounding (std 1e-9) decides every test row unless its std is floored."""
    rng = np.random.default_rng(15)
    lab = ["a", "b"] * 20
    xtr = np.stack([np.array([0.0 if c == "a" else 3.0 for c in lab]) + rng.normal(0, 0.3, 40),
                    1.0 + rng.normal(0, 1e-9, 40)], axis=1)
    xte = xtr + [0.0, 1e-3]  # a 1e-3 shift in the near-constant feature: a million of its training stds
    assert linear_probe_accuracy(xtr, lab, xtr, lab) == 1.0
    assert linear_probe_accuracy(xte[:, :1], lab, xte[:, :1], lab) == 1.0
    assert linear_probe_accuracy(xtr, lab, xte, lab) == 0.5  # every row to one class
    assert linear_probe_predict(xtr, lab, xte) == linear_probe_predict(xtr, lab, xte, std_floor=[1e-8, 1e-8])
    assert linear_probe_accuracy(xtr, lab, xte, lab, std_floor=[1e-8, 0.1]) == 1.0
    with pytest.raises(DataError, match="std_floor"):
        linear_probe_predict(xtr, lab, xte, std_floor=0.0)

"""Tests of jaxgest.metrics.transfer_errors: content error (DTW on both hands) and windowed style error (paper 000)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.runtime.errors import DataError
from jaxgest.metrics import (
    arm_velocities,
    content_error,
    content_error_components,
    dtw_numpy,
    hands_metres,
    style_error,
    style_error_components,
    summarize_errors,
    window_for_fps,
    window_statistics,
)

from metrics_testing import random_walk

SETTINGS = settings(max_examples=25, deadline=None)


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
    a = random_walk(np.random.default_rng(7), 50, 6) * 0.01
    for b in (a, np.repeat(a, 2, axis=0)):
        assert content_error(a, b) == {"mean": 0.0, "worst": 0.0, "w25": 0.0}


def test_content_error_matches_reference_alignment():
    rng = np.random.default_rng(8)
    a, b = random_walk(rng, 45, 6), random_walk(rng, 38, 6)
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
    x, y = random_walk(rng, 40, 6), random_walk(rng, 44, 6)
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

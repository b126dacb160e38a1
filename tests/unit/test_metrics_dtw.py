"""Tests of jaxgest.metrics.dtw: exact DTW (JAX wavefront vs NumPy vs fastdtw), paths, buckets, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.runtime.errors import DataError
from jaxgest.metrics import (
    dtw,
    dtw_numpy,
    dtw_wavefront,
    path_distances,
)

from metrics_testing import random_walk

SETTINGS = settings(max_examples=25, deadline=None)


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
    a, b = (random_walk(rng, n), random_walk(rng, m)) if walk else (rng.normal(size=(n, 3)), rng.normal(size=(m, 3)))
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
    a = random_walk(np.random.default_rng(1), 57, 6)
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
    a = random_walk(np.random.default_rng(2), 40)
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
    a, b = random_walk(rng, 150, 6), random_walk(rng, 131, 6)
    cost, path = dtw(a, b)
    ref_cost, ref_path = dtw_numpy(a, b)
    np.testing.assert_allclose(cost, ref_cost, rtol=1e-12)
    np.testing.assert_array_equal(path, ref_path)


def test_dtw_not_worse_than_fastdtw():
    fastdtw = pytest.importorskip("fastdtw")
    rng = np.random.default_rng(6)
    for n, m in [(90, 70), (120, 121), (5, 80)]:
        a, b = random_walk(rng, n, 6), random_walk(rng, m, 6)
        approx, approx_path = fastdtw.fastdtw(a, b, radius=1, dist=2)
        cost, _ = dtw(a, b)
        assert cost <= approx + 1e-9
        assert cost <= path_distances(a, b, np.asarray(approx_path)).sum() + 1e-9


def test_dtw_equals_fastdtw_with_full_radius():
    fastdtw = pytest.importorskip("fastdtw")
    rng = np.random.default_rng(7)
    for n, m in [(30, 25), (12, 40), (1, 9)]:
        a, b = random_walk(rng, n, 6), random_walk(rng, m, 6)
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

"""Rotation conversions against scipy's Rotation (independent reference), round trips, edge cases."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from jaxgest.motion import rotations as R

Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
finite = st.floats(-1.0, 1.0, allow_nan=False, width=64)
quats = arrays(np.float64, (7, 4), elements=finite).filter(lambda q: np.all(np.linalg.norm(q, axis=-1) > 0.1))
SETTINGS = settings(max_examples=30, deadline=None)


def to_scipy(q):
    return Rotation.from_quat(np.concatenate([q[..., 1:], q[..., :1]], axis=-1))


def from_scipy(r):
    x = r.as_quat()
    return np.concatenate([x[..., 3:], x[..., :3]], axis=-1)


def same_rotation(q1, q2, atol):
    d = np.minimum(np.abs(q1 - q2).max(-1), np.abs(q1 + q2).max(-1))
    assert d.max() < atol, d.max()


@SETTINGS
@given(quats, st.sampled_from(ORDERS))
def test_euler_round_trip_against_scipy(q, order):
    q = R.quat_normalize(q)
    eul = R.quat_to_euler(q, order)
    ref = Rotation.from_euler(order, eul, degrees=True)  # uppercase = intrinsic, as BVH
    same_rotation(R.euler_to_quat(eul, order), from_scipy(ref), 1e-9)
    same_rotation(R.euler_to_quat(eul, order), q, 2e-7)  # ~1e-7 only within 1e-7 of gimbal lock


@SETTINGS
@given(quats)
def test_matrix_expmap_6d_against_scipy(q):
    q = R.quat_normalize(q)
    ref = to_scipy(q)
    np.testing.assert_allclose(R.quat_to_matrix(q), ref.as_matrix(), atol=1e-12)
    same_rotation(R.matrix_to_quat(ref.as_matrix()), q, 1e-9)
    ev = R.quat_to_expmap(q)
    # Same rotation vector up to the 2*pi ambiguity at angle pi.
    np.testing.assert_allclose(R.expmap_to_matrix(ev), ref.as_matrix(), atol=1e-9)
    assert np.all(np.linalg.norm(ev, axis=-1) <= np.pi + 1e-9)
    np.testing.assert_allclose(R.sixd_to_matrix(R.quat_to_6d(q)), ref.as_matrix(), atol=1e-9)


@SETTINGS
@given(arrays(np.float64, (5, 3), elements=st.floats(-3.0, 3.0, width=64)))
def test_expmap_round_trip(v):
    # Inside the ball of radius pi the log map inverts the exp map exactly.
    v = v * np.minimum(1.0, 3.0 / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12))
    np.testing.assert_allclose(R.quat_to_expmap(R.expmap_to_quat(v)), v, atol=1e-9)
    np.testing.assert_allclose(R.expmap_to_quat(v), from_scipy(Rotation.from_rotvec(v)) * np.sign(
        from_scipy(Rotation.from_rotvec(v))[..., :1] * R.expmap_to_quat(v)[..., :1] + 1e-300), atol=1e-9)


@SETTINGS
@given(quats, quats)
def test_quat_mul_inv_rotate_against_scipy(a, b):
    a, b = R.quat_normalize(a), R.quat_normalize(b)
    same_rotation(R.quat_mul(a, b), from_scipy(to_scipy(a) * to_scipy(b)), 1e-9)
    same_rotation(R.quat_mul(a, R.quat_inv(a)), np.tile([1.0, 0, 0, 0], (7, 1)), 1e-12)
    v = b[:, 1:]
    np.testing.assert_allclose(R.quat_rotate(a, v), to_scipy(a).apply(v), atol=1e-12)


def test_near_zero_and_pi_are_accurate_and_have_finite_gradients():
    for angle in [0.0, 1e-9, 1e-5, np.pi - 1e-7, np.pi]:
        v = np.array([angle, 0.0, 0.0])
        np.testing.assert_allclose(R.quat_to_expmap(R.expmap_to_quat(v)), v, atol=1e-7)
    f = lambda v: jnp.sum(R.quat_to_expmap(R.expmap_to_quat(v)))  # noqa: E731
    g = jax.grad(f)(jnp.zeros(3, jnp.float32))
    np.testing.assert_allclose(np.asarray(g), np.ones(3), atol=1e-6)
    g2 = jax.grad(lambda q: jnp.sum(R.quat_to_expmap(q)))(jnp.asarray([1.0, 0.0, 0.0, 0.0], jnp.float32))
    assert np.all(np.isfinite(np.asarray(g2)))


def test_jax_and_numpy_paths_agree_and_jit():
    rng = np.random.default_rng(0)
    q = R.quat_normalize(rng.normal(size=(10, 4)))
    for name in ["quat_to_expmap", "quat_to_matrix", "quat_to_6d", "quat_angle"]:
        fn = getattr(R, name)
        np.testing.assert_allclose(np.asarray(jax.jit(fn)(jnp.asarray(q, jnp.float32))), fn(q), atol=2e-5)
    e = rng.uniform(-170, 170, size=(10, 3))
    out = jax.jit(lambda x: R.euler_to_quat(x, "ZXY"))(jnp.asarray(e, jnp.float32))
    assert isinstance(out, jax.Array)
    same_rotation(np.asarray(out, np.float64), R.euler_to_quat(e, "ZXY"), 1e-5)


def test_gimbal_lock_reconstructs_rotation():
    for order in ORDERS:
        q = R.euler_to_quat(np.array([[30.0, 90.0, 20.0], [10.0, -90.0, -45.0]]), order)
        same_rotation(R.euler_to_quat(R.quat_to_euler(q, order), order), q, 1e-7)


def test_bad_order_rejected():
    with pytest.raises(ValueError, match="permutation"):
        R.euler_to_quat(np.zeros(3), "XXY")


def test_quat_between_and_slerp():
    u, v = np.array([1.0, 2.0, 0.0]), np.array([0.0, 0.0, 3.0])
    np.testing.assert_allclose(R.quat_rotate(R.quat_between(u, v), u), v / 3 * np.linalg.norm(u), atol=1e-12)
    np.testing.assert_allclose(R.quat_rotate(R.quat_between(u, -u), u), -u, atol=1e-12)
    a, b = R.euler_to_quat(np.array([0.0, 0, 0]), "XYZ"), R.euler_to_quat(np.array([90.0, 0, 0]), "XYZ")
    same_rotation(R.quat_slerp(a, b, 0.5), R.euler_to_quat(np.array([45.0, 0, 0]), "XYZ"), 1e-12)

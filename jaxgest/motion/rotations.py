"""Rotation conversions: quaternions, exponential maps, matrices, 6-D, Euler angles (docs/design.md §7).

Conventions
-----------
* Quaternions are ``(w, x, y, z)``, Hamilton product, active rotations of column vectors:
  ``quat_rotate(q, v) = q v q*``.
* Exponential map ("logarithmic map" of paper 000 §3.1, Grassia 1998): ``axis * angle`` (full angle).
* Matrices ``(..., 3, 3)`` act on column vectors: ``v' = R @ v``.
* 6-D representation (Zhou et al. 2019; paper 001's "2-axis rotation"): the first two *columns* of the
  matrix, concatenated ``[R[:, 0], R[:, 1]]``.
* Euler angles in degrees for a channel ``order`` such as ``"ZXY"`` (BVH channel order): the rotation is
  ``R = R_Z(a0) @ R_X(a1) @ R_Y(a2)`` (intrinsic, applied in the listed order), as in every BVH reader.

Every function is batched over leading axes and works on NumPy arrays (computing in float64, for exact
file I/O) or on JAX arrays / tracers (``jax.numpy``, jit-able and differentiable). Near angle 0 and pi the
formulas use Taylor branches behind a double ``where`` so values and gradients stay finite.

References: Grassia 1998 (exp-map); Zhou et al. 2019 (6-D); Shepperd 1978 (matrix -> quaternion).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

_AXES = {"X": 0, "Y": 1, "Z": 2}


def _xp(*arrays):
    """NumPy for NumPy inputs (float64 precision), jax.numpy for anything traced or on device."""
    return jnp if any(isinstance(a, jax.Array) for a in arrays) else np


def _asarray(xp, x):
    if xp is np:
        return np.asarray(x, dtype=np.float64)
    x = jnp.asarray(x)
    return x if jnp.issubdtype(x.dtype, jnp.floating) else x.astype(jnp.float32)


def _norm(xp, v, axis=-1, keepdims=False):
    return xp.sqrt(xp.sum(v * v, axis=axis, keepdims=keepdims))


def quat_identity(shape=(), like=None):
    """Identity quaternions of the given leading shape."""
    xp = _xp(like) if like is not None else np
    q = xp.zeros(tuple(shape) + (4,), dtype=xp.float64 if xp is np else jnp.float32)
    if xp is np:
        q[..., 0] = 1.0
        return q
    return q.at[..., 0].set(1.0)


def quat_normalize(q):
    """Unit quaternions ``(..., 4)``."""
    xp = _xp(q)
    q = _asarray(xp, q)
    return q / xp.maximum(_norm(xp, q, keepdims=True), 1e-12)


def quat_canonicalize(q):
    """Sign-canonical quaternion (w >= 0), the same rotation: used before log maps and comparisons."""
    xp = _xp(q)
    q = _asarray(xp, q)
    return xp.where(q[..., :1] < 0, -q, q)


def quat_mul(a, b):
    """Hamilton product ``a * b`` of ``(..., 4)`` quaternions (rotation ``b`` first, then ``a``)."""
    xp = _xp(a, b)
    a, b = _asarray(xp, a), _asarray(xp, b)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return xp.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_inv(q):
    """Inverse of unit quaternions (the conjugate)."""
    xp = _xp(q)
    q = _asarray(xp, q)
    return xp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_rotate(q, v):
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)``."""
    xp = _xp(q, v)
    q, v = _asarray(xp, q), _asarray(xp, v)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * xp.cross(u, v)
    return v + w * t + xp.cross(u, t)


def quat_angle(q):
    """Rotation angle in radians in [0, pi] of ``(..., 4)`` unit quaternions."""
    xp = _xp(q)
    q = quat_canonicalize(q)
    return 2.0 * xp.arctan2(_norm(xp, q[..., 1:]), q[..., 0])


def expmap_to_quat(v):
    """Exponential map ``axis * angle (..., 3)`` -> unit quaternion ``(..., 4)``.

    Finite value and gradient at zero rotation (Taylor branch of sin(t/2)/t).
    References: Grassia 1998, eq. 3-4.
    """
    xp = _xp(v)
    v = _asarray(xp, v)
    t2 = xp.sum(v * v, axis=-1, keepdims=True)
    small = t2 < 1e-8
    t2_safe = xp.where(small, 1.0, t2)
    t = xp.sqrt(t2_safe)
    half_sinc = xp.where(small, 0.5 - t2 / 48.0, xp.sin(0.5 * t) / t)
    w = xp.where(small, 1.0 - t2 / 8.0, xp.cos(0.5 * t))
    return xp.concatenate([w, v * half_sinc], axis=-1)


def quat_to_expmap(q):
    """Unit quaternion ``(..., 4)`` -> exponential map ``(..., 3)`` with angle in [0, pi].

    The quaternion is sign-canonicalised (w >= 0) first so the shortest rotation is returned. Finite value
    and gradient at zero rotation.
    References: Grassia 1998.
    """
    xp = _xp(q)
    q = quat_canonicalize(quat_normalize(q))
    w, u = q[..., :1], q[..., 1:]
    s2 = xp.sum(u * u, axis=-1, keepdims=True)
    small = s2 < 1e-10
    s_safe = xp.sqrt(xp.where(small, 1.0, s2))
    w_safe = xp.where(small, w, 1.0)  # w ~ 1 where small; 1 elsewhere keeps the unused branch finite
    # angle / sin(angle/2), angle = 2 atan2(s, w); Taylor: 2/w (1 - s^2 / (3 w^2)) near s = 0.
    factor = xp.where(small, 2.0 / w_safe * (1.0 - s2 / (3.0 * w_safe * w_safe)), 2.0 * xp.arctan2(s_safe, w) / s_safe)
    return u * factor


def quat_to_matrix(q):
    """Unit quaternion ``(..., 4)`` -> rotation matrix ``(..., 3, 3)``."""
    xp = _xp(q)
    q = quat_normalize(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rows = [
        xp.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)], axis=-1),
        xp.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)], axis=-1),
        xp.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)], axis=-1),
    ]
    return xp.stack(rows, axis=-2)


def matrix_to_quat(m):
    """Rotation matrix ``(..., 3, 3)`` -> unit quaternion ``(..., 4)`` with w >= 0.

    Shepperd's method: the four candidate formulas are all computed and the numerically best one (largest
    diagonal term) is selected per element, so it is accurate near angle pi too.
    References: Shepperd 1978.
    """
    xp = _xp(m)
    m = _asarray(xp, m)
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    tr = m00 + m11 + m22
    cands = xp.stack(
        [
            xp.stack([1 + tr, m21 - m12, m02 - m20, m10 - m01], axis=-1),
            xp.stack([m21 - m12, 1 + m00 - m11 - m22, m01 + m10, m02 + m20], axis=-1),
            xp.stack([m02 - m20, m01 + m10, 1 - m00 + m11 - m22, m12 + m21], axis=-1),
            xp.stack([m10 - m01, m02 + m20, m12 + m21, 1 - m00 - m11 + m22], axis=-1),
        ],
        axis=-2,
    )  # (..., 4, 4); row i is 4 * q_i * q
    diag = xp.stack([tr, m00, m11, m22], axis=-1)
    best = xp.argmax(diag, axis=-1)
    if xp is np:
        q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    else:
        q = jnp.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    return quat_canonicalize(quat_normalize(q))


def expmap_to_matrix(v):
    """Exponential map ``(..., 3)`` -> rotation matrix ``(..., 3, 3)``."""
    return quat_to_matrix(expmap_to_quat(v))


def matrix_to_expmap(m):
    """Rotation matrix ``(..., 3, 3)`` -> exponential map ``(..., 3)``."""
    return quat_to_expmap(matrix_to_quat(m))


def quat_to_6d(q):
    """Unit quaternion -> 6-D rotation ``(..., 6)``: the first two matrix columns, concatenated.

    References: Zhou et al. 2019 (continuity of rotation representations); Ghorbani et al. 2023 §3.2
    ("2-axis rotation matrices").
    """
    xp = _xp(q)
    m = quat_to_matrix(q)
    return xp.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def sixd_to_matrix(d6):
    """6-D rotation ``(..., 6)`` -> rotation matrix ``(..., 3, 3)`` by Gram-Schmidt.

    References: Zhou et al. 2019, section 4.
    """
    xp = _xp(d6)
    d6 = _asarray(xp, d6)
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / xp.maximum(_norm(xp, a1, keepdims=True), 1e-12)
    a2p = a2 - xp.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = a2p / xp.maximum(_norm(xp, a2p, keepdims=True), 1e-12)
    b3 = xp.cross(b1, b2)
    return xp.stack([b1, b2, b3], axis=-1)


def sixd_to_quat(d6):
    """6-D rotation -> unit quaternion (w >= 0)."""
    return matrix_to_quat(sixd_to_matrix(d6))


def _check_order(order: str) -> str:
    order = order.upper()
    if len(order) != 3 or set(order) != {"X", "Y", "Z"}:
        raise ValueError(f"Euler order must be a permutation of 'XYZ', got {order!r}")
    return order


def _axis_quat(xp, angle_rad, axis: int):
    half = 0.5 * angle_rad
    c, s = xp.cos(half), xp.sin(half)
    z = xp.zeros_like(s)
    comps = [z, z, z]
    comps[axis] = s
    return xp.stack([c] + comps, axis=-1)


def euler_to_quat(angles_deg, order: str):
    """Euler angles in degrees ``(..., 3)`` in channel order ``order`` -> unit quaternion ``(..., 4)``.

    ``angles_deg[..., i]`` is the rotation about axis ``order[i]``; the result is
    ``q = q_{order[0]} * q_{order[1]} * q_{order[2]}`` (BVH convention).
    """
    order = _check_order(order)
    xp = _xp(angles_deg)
    a = _asarray(xp, angles_deg) * (np.pi / 180.0)
    q = _axis_quat(xp, a[..., 0], _AXES[order[0]])
    q = quat_mul(q, _axis_quat(xp, a[..., 1], _AXES[order[1]]))
    return quat_mul(q, _axis_quat(xp, a[..., 2], _AXES[order[2]]))


def quat_to_euler(q, order: str):
    """Unit quaternion ``(..., 4)`` -> Euler angles in degrees ``(..., 3)`` for channel order ``order``.

    Inverse of :func:`euler_to_quat` with the middle angle in [-90, 90] degrees. For
    ``R = R_i(a) R_j(b) R_k(c)``: ``sin b = s R[i,k]``, ``a = atan2(-s R[j,k], R[k,k])``,
    ``c = atan2(-s R[i,j], R[i,i])``, with ``s = +1`` for cyclic orders (XYZ, YZX, ZXY) and -1 otherwise.
    At gimbal lock (|sin b| ~ 1) ``c`` is set to 0 and ``a`` absorbs the remaining rotation.
    """
    order = _check_order(order)
    xp = _xp(q)
    m = quat_to_matrix(q)
    i, j, k = (_AXES[c] for c in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    sb = s * m[..., i, k]
    cb = xp.sqrt(m[..., i, i] ** 2 + m[..., i, j] ** 2)  # atan2 keeps full precision near +/-90 degrees
    b = xp.arctan2(sb, cb)
    lock = cb < 1e-7  # outside: angle error ~ eps/cb; inside: dropping c costs ~cb
    a = xp.arctan2(-s * m[..., j, k], m[..., k, k])
    c = xp.arctan2(-s * m[..., i, j], m[..., i, i])
    # Gimbal lock: R = R_i(a') R_j(b) with c = 0; then R e_j = R_i(a') e_j gives a' from column j.
    a_lock = xp.arctan2(s * m[..., k, j], m[..., j, j])
    a = xp.where(lock, a_lock, a)
    c = xp.where(lock, 0.0, c)
    return xp.stack([a, b, c], axis=-1) * (180.0 / np.pi)


def quat_between(u, v):
    """Shortest-arc unit quaternion rotating direction ``u`` onto direction ``v`` (both ``(..., 3)``)."""
    xp = _xp(u, v)
    u = _asarray(xp, u)
    v = _asarray(xp, v)
    u = u / xp.maximum(_norm(xp, u, keepdims=True), 1e-12)
    v = v / xp.maximum(_norm(xp, v, keepdims=True), 1e-12)
    d = xp.sum(u * v, axis=-1, keepdims=True)
    c = xp.cross(u, v)
    # Opposite vectors: any axis orthogonal to u.
    alt = xp.cross(u, xp.broadcast_to(xp.asarray([1.0, 0.0, 0.0], dtype=u.dtype), u.shape))
    alt2 = xp.cross(u, xp.broadcast_to(xp.asarray([0.0, 1.0, 0.0], dtype=u.dtype), u.shape))
    alt = xp.where(_norm(xp, alt, keepdims=True) < 1e-6, alt2, alt)
    opposite = d < -1.0 + 1e-9
    q = xp.concatenate([1.0 + d, c], axis=-1)
    q = xp.where(opposite, xp.concatenate([xp.zeros_like(d), alt], axis=-1), q)
    return quat_normalize(q)


def quat_slerp(a, b, t):
    """Spherical interpolation between unit quaternions (shortest path), ``t`` broadcastable ``(...,)``."""
    xp = _xp(a, b)
    a, b = _asarray(xp, a), _asarray(xp, b)
    d = xp.sum(a * b, axis=-1, keepdims=True)
    b = xp.where(d < 0, -b, b)
    d = xp.abs(d)
    t = _asarray(xp, t)[..., None]
    theta = xp.arccos(xp.clip(d, -1.0, 1.0))
    lin = d > 1.0 - 1e-6
    sin_t = xp.where(lin, 1.0, xp.sin(theta))
    wa = xp.where(lin, 1.0 - t, xp.sin((1.0 - t) * theta) / sin_t)
    wb = xp.where(lin, t, xp.sin(t * theta) / sin_t)
    return quat_normalize(wa * a + wb * b)


def quat_unroll(q, axis: int = 0):
    """Flip quaternion signs along ``axis`` (time) so consecutive quaternions have positive dot products.

    NumPy only (data preparation): removes the sign discontinuities that would otherwise make velocities
    and interpolation jump.
    """
    q = np.array(q, dtype=np.float64, copy=True)
    q = np.moveaxis(q, axis, 0)
    for t in range(1, q.shape[0]):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t][flip] *= -1
    return np.moveaxis(q, 0, axis)


def angular_error_rad(pred: jax.Array, target: jax.Array) -> jax.Array:
    """Geodesic angle between the rotations of two exp-map arrays ``(..., 3J) -> (..., J)`` in [0, pi]."""
    if pred.shape != target.shape:
        raise ValueError(f"angular_error_rad: shapes differ, {pred.shape} vs {target.shape}")
    shape = pred.shape[:-1] + (pred.shape[-1] // 3, 3)
    qp = expmap_to_quat(jnp.reshape(pred, shape))
    qt = expmap_to_quat(jnp.reshape(target, shape))
    qt_conj = jnp.concatenate([qt[..., :1], -qt[..., 1:]], axis=-1)  # inverse of a unit quaternion
    return quat_angle(quat_mul(qt_conj, qp))

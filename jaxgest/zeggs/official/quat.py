"""Quaternion maths of the ZeroEGGS authors' code, written once for NumPy and jax.numpy.

Every function takes ``xp`` (``numpy`` or ``jax.numpy``) so that the feature extraction (NumPy, float64, as
the authors' ``anim/quat.py``) and the decoder's root integration (jnp, float32, as their ``anim/tquat.py``)
are the same formulas. Quaternions are ``(..., 4)`` ``(w, x, y, z)``; ``mul(x, y)`` is the Hamilton product
``x y``; ``mul_vec(q, v)`` rotates ``v`` by ``q``. The small-angle branches and the ``eps`` added to norms are
theirs (they change results at the 1e-6 level, so parity needs them).

References: the authors' ``ZEGGS/anim/quat.py`` and ``ZEGGS/anim/tquat.py`` (ubisoft-laforge-ZeroEGGS);
Ghorbani et al. 2023, §3.3 (pose state, root update).
"""

from __future__ import annotations

import numpy as np


def mul(x, y, xp=np):
    """Hamilton product ``x y`` of ``(..., 4)`` quaternions."""
    x0, x1, x2, x3 = x[..., 0:1], x[..., 1:2], x[..., 2:3], x[..., 3:4]
    y0, y1, y2, y3 = y[..., 0:1], y[..., 1:2], y[..., 2:3], y[..., 3:4]
    return xp.concatenate([
        y0 * x0 - y1 * x1 - y2 * x2 - y3 * x3,
        y0 * x1 + y1 * x0 - y2 * x3 + y3 * x2,
        y0 * x2 + y1 * x3 + y2 * x0 - y3 * x1,
        y0 * x3 - y1 * x2 + y2 * x1 + y3 * x0], axis=-1)


def _cross(a, b, xp=np):
    return xp.concatenate([
        a[..., 1:2] * b[..., 2:3] - a[..., 2:3] * b[..., 1:2],
        a[..., 2:3] * b[..., 0:1] - a[..., 0:1] * b[..., 2:3],
        a[..., 0:1] * b[..., 1:2] - a[..., 1:2] * b[..., 0:1]], axis=-1)


def mul_vec(q, v, xp=np):
    """``v`` rotated by ``q``: ``v + w t + u x t`` with ``t = 2 u x v``."""
    t = 2.0 * _cross(q[..., 1:], v, xp)
    return v + q[..., 0:1] * t + _cross(q[..., 1:], t, xp)


def inv(q, xp=np):
    """Conjugate (the inverse of a unit quaternion)."""
    return q * xp.reshape(xp.asarray([1.0, -1.0, -1.0, -1.0], dtype=q.dtype), (1,) * (q.ndim - 1) + (4,))


def qabs(q, xp=np):
    """The same rotation with ``w >= 0`` (theirs: ``w > 0`` keeps, otherwise negates)."""
    return xp.where(q[..., 0:1] > 0.0, q, -q)


def normalize(q, eps: float = 0.0, xp=np):
    return q / (xp.sqrt(xp.sum(q * q, axis=-1, keepdims=True)) + eps)


def to_helical(q, eps: float = 1e-5, xp=np):
    """Scaled angle-axis ``2 log(q)`` (NumPy branch of theirs: ``atan2(|u|, w) / |u|``, 1 below ``eps``)."""
    length = xp.sqrt(xp.sum(xp.square(q[..., 1:]), axis=-1, keepdims=True))
    safe = xp.where(length < eps, xp.ones_like(length), length)
    half = xp.where(length < eps, xp.ones_like(length), xp.arctan2(length, q[..., 0:1]) / safe)
    return 2.0 * half * q[..., 1:]


def from_helical(v, eps: float = 1e-5, xp=np):
    """``exp(v / 2)`` as their torch ``quat_from_helical``: below ``eps`` the normalised ``(1, v/2)``."""
    x = v / 2.0
    half = xp.sqrt(xp.sum(x * x, axis=-1, keepdims=True))
    small = half < eps
    approx = normalize(xp.concatenate([xp.ones_like(half), x], axis=-1), 1e-5, xp)
    safe = xp.where(small, xp.ones_like(half), half)
    exact = xp.concatenate([xp.cos(half), x * (xp.sin(safe) / safe)], axis=-1)
    return xp.where(small, approx, exact)


def between(a, b, xp=np):
    """The (unnormalised) rotation taking direction ``a`` to ``b``."""
    w = xp.sqrt(xp.sum(a * a, axis=-1) * xp.sum(b * b, axis=-1))[..., None] + xp.sum(a * b, axis=-1)[..., None]
    return xp.concatenate([w, _cross(a, b, xp)], axis=-1)


def unroll(q: np.ndarray) -> np.ndarray:
    """Flip signs along the time axis (axis 0) so consecutive quaternions lie in the same hemisphere."""
    y = np.array(q, dtype=np.float64, copy=True)
    for i in range(1, len(y)):
        flip = np.sum(y[i] * y[i - 1], axis=-1) < 0.0
        y[i][flip] = -y[i][flip]
    return y


def fk(lrot: np.ndarray, lpos: np.ndarray, parents) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations and positions ``(F, J, 4)``, ``(F, J, 3)`` (parents before children)."""
    gr, gp = [lrot[..., :1, :]], [lpos[..., :1, :]]
    for i in range(1, len(parents)):
        p = parents[i]
        gp.append(mul_vec(gr[p], lpos[..., i:i + 1, :]) + gp[p])
        gr.append(mul(gr[p], lrot[..., i:i + 1, :]))
    return np.concatenate(gr, axis=-2), np.concatenate(gp, axis=-2)


def two_axis(q, xp=np):
    """The 2-axis rotation ``(..., 2, 3)``: the rotated x and y axes (their ``ltxy``)."""
    ones = xp.ones_like(q[..., :1])
    zeros = xp.zeros_like(q[..., :1])
    x = mul_vec(q, xp.concatenate([ones, zeros, zeros], axis=-1), xp)
    y = mul_vec(q, xp.concatenate([zeros, ones, zeros], axis=-1), xp)
    return xp.stack([x, y], axis=-2)


def from_two_axis(xy: np.ndarray, eps: float = 1e-10) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` from 2-axis rotations ``(..., 2, 3)`` (Gram-Schmidt as their
    ``xform_orthogonalize_from_xy``, then the matrix-to-quaternion of their ``quat.from_xform``)."""
    xy = np.asarray(xy, np.float64)
    xa = xy[..., 0, :]
    za = np.cross(xa, xy[..., 1, :])
    ya = np.cross(za, xa)
    rows = [a / (np.linalg.norm(a, axis=-1, keepdims=True) + eps) for a in (xa, ya, za)]
    m = np.stack(rows, axis=-1)  # columns are the axes: their transpose of the stacked rows
    return _from_matrix(m, eps)


def _from_matrix(ts: np.ndarray, eps: float) -> np.ndarray:
    """Their ``quat.from_xform`` (the four branches of the trace method), then normalised."""
    t = ts[..., 0, 0] + ts[..., 1, 1] + ts[..., 2, 2]
    qs = np.empty(ts.shape[:-2] + (4,))
    s = 0.5 / np.sqrt(np.maximum(t + 1, eps))
    a = np.stack([0.25 / s, s * (ts[..., 2, 1] - ts[..., 1, 2]), s * (ts[..., 0, 2] - ts[..., 2, 0]),
                  s * (ts[..., 1, 0] - ts[..., 0, 1])], axis=-1)
    s = 2.0 * np.sqrt(np.maximum(1.0 + ts[..., 0, 0] - ts[..., 1, 1] - ts[..., 2, 2], eps))
    b = np.stack([(ts[..., 2, 1] - ts[..., 1, 2]) / s, s * 0.25, (ts[..., 0, 1] + ts[..., 1, 0]) / s,
                  (ts[..., 0, 2] + ts[..., 2, 0]) / s], axis=-1)
    s = 2.0 * np.sqrt(np.maximum(1.0 + ts[..., 1, 1] - ts[..., 0, 0] - ts[..., 2, 2], eps))
    c = np.stack([(ts[..., 0, 2] - ts[..., 2, 0]) / s, (ts[..., 0, 1] + ts[..., 1, 0]) / s, s * 0.25,
                  (ts[..., 1, 2] + ts[..., 2, 1]) / s], axis=-1)
    s = 2.0 * np.sqrt(np.maximum(1.0 + ts[..., 2, 2] - ts[..., 0, 0] - ts[..., 1, 1], eps))
    d = np.stack([(ts[..., 1, 0] - ts[..., 0, 1]) / s, (ts[..., 0, 2] + ts[..., 2, 0]) / s,
                  (ts[..., 1, 2] + ts[..., 2, 1]) / s, s * 0.25], axis=-1)
    c0 = (ts[..., 0, 0] > ts[..., 1, 1]) & (ts[..., 0, 0] > ts[..., 2, 2])
    c1 = ts[..., 1, 1] > ts[..., 2, 2]
    qs = np.where((t > 0)[..., None], a, np.where(c0[..., None], b, np.where(c1[..., None], c, d)))
    return normalize(qs)

"""Exact dynamic time warping: a JAX anti-diagonal wavefront and a plain NumPy reference.

The paper aligns clips with FastDTW [Salvador & Chan 2007], a linear-time *approximation* of DTW. Following
docs/design.md §5 we compute the exact DTW it approximates (same step pattern, same Euclidean frame distance, same
cost convention), so a FastDTW cost is always >= ours.

Conventions (shared by :func:`dtw` and :func:`dtw_numpy`):
  * frame distance d(i, j) = ||a_i - b_j||_2;
  * steps (i-1, j-1), (i-1, j), (i, j-1); on exact ties the predecessor is chosen in that order;
  * cost = sum of d(i, j) over the cells of the optimal path (the FastDTW convention: no step weights,
    no normalisation by the path length);
  * path = (K, 2) int array of (i, j) pairs from (0, 0) to (N-1, M-1), monotone and continuous.

References: Sakoe & Chiba 1978 (DTW); Salvador & Chan 2007 (FastDTW), as used in Kuriyama et al. 2022, eq. 14.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.runtime.errors import DataError

# Predecessor codes stored by the forward pass.
_DIAG, _UP, _LEFT = 0, 1, 2
_STEP = {_DIAG: (1, 1), _UP: (1, 0), _LEFT: (0, 1)}
_BUCKET = 64  # lengths are padded (see _bucket) so clips of similar length share one compilation


def _bucket(k: int) -> int:
    """Padded length of a k-frame sequence: a multiple of 64 up to 256, then the next 2^j or 1.5 * 2^j.

    At most 1.5x (above 256 frames) extra work per axis, and few distinct shapes -- hence few compilations
    -- over a dataset of clips of many lengths.
    """
    if k <= 4 * _BUCKET:
        return -(-k // _BUCKET) * _BUCKET
    size = 4 * _BUCKET
    while True:
        for candidate in (size, size * 3 // 2, 2 * size):
            if k <= candidate:
                return candidate
        size *= 2


def _check_pair(a, b) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(a)
    b = np.asarray(b)
    if a.ndim == 1:
        a = a[:, None]
    if b.ndim == 1:
        b = b[:, None]
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise DataError(f"dtw: expected (N, C) and (M, C) sequences, got shapes {a.shape} and {b.shape}")
    if len(a) == 0 or len(b) == 0:
        raise DataError(f"dtw: empty sequence (shapes {a.shape} and {b.shape})")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise DataError("dtw: sequences contain NaN or inf")
    return a, b


@jax.jit
def dtw_wavefront(a: jax.Array, b: jax.Array, n: jax.Array, m: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Forward DTW pass over anti-diagonals d = i + j (one vectorised step per diagonal).

    a: (N, C), b: (M, C) -- possibly zero-padded; n, m: the true lengths (int scalars). Padding is harmless:
    a cell only depends on cells with smaller indices, so cells with i < n, j < m never see padded frames.
    Returns ``(cost, pred)``: cost = accumulated cost at (n-1, m-1) (in the inputs' float dtype) and pred
    (N+M-1, N) int8, pred[i+j, i] = predecessor code of cell (i, j) (0 diag, 1 up (i-1, j), 2 left (i, j-1)).
    Memory is O((N+M) N) bytes for pred; time O((N+M) N C).

    References: Sakoe & Chiba 1978, the DTW recursion R(i,j) = d(i,j) + min(R(i-1,j-1), R(i-1,j), R(i,j-1)).
    """
    chex.assert_rank([a, b], 2)
    big_n, big_m = a.shape[0], b.shape[0]
    i = jnp.arange(big_n)
    inf = jnp.array(jnp.inf, a.dtype)
    shift = lambda x: jnp.concatenate([jnp.full((1,), inf), x[:-1]])  # x[i-1], inf at i = 0

    def step(carry, d):
        prev1, prev2 = carry  # R on diagonals d-1 and d-2, indexed by i
        j = d - i
        valid = (j >= 0) & (j < big_m)
        dist = jnp.sqrt(jnp.sum((a - b[jnp.clip(j, 0, big_m - 1)]) ** 2, axis=-1))
        cand = jnp.stack([shift(prev2), shift(prev1), prev1])  # diag, up, left
        pred = jnp.argmin(cand, axis=0).astype(jnp.int8)  # first minimum: diag, then up, then left
        best = jnp.min(cand, axis=0)
        best = jnp.where((i == 0) & (j == 0), jnp.zeros((), a.dtype), best)
        new = jnp.where(valid, dist + best, inf)
        return (new, prev1), (pred, new[jnp.clip(n - 1, 0, big_n - 1)])

    init = (jnp.full((big_n,), inf), jnp.full((big_n,), inf))
    _, (pred, at_n) = jax.lax.scan(step, init, jnp.arange(big_n + big_m - 1))
    return at_n[n + m - 2], pred


def _float64_scope():
    """A context in which JAX computes in float64 (``jax.enable_x64``; older JAX: ``jax.experimental``)."""
    if hasattr(jax, "enable_x64"):
        return jax.enable_x64(True)
    from jax.experimental import enable_x64  # JAX < 0.7

    return enable_x64()


def _backtrack(pred: np.ndarray, n: int, m: int) -> np.ndarray:
    """Follow the stored predecessors from (n-1, m-1) back to (0, 0); (K, 2) int64 path, start first.

    References: Sakoe & Chiba 1978 (optimal path by backtracking the DTW recursion).
    """
    i, j = n - 1, m - 1
    path = [(i, j)]
    while i > 0 or j > 0:
        if i == 0:
            j -= 1
        elif j == 0:
            i -= 1
        else:
            di, dj = _STEP[int(pred[i + j, i])]
            i, j = i - di, j - dj
        path.append((i, j))
    return np.asarray(path[::-1], dtype=np.int64)


def path_distances(a, b, path: np.ndarray) -> np.ndarray:
    """Euclidean frame distances ``(K,)`` (float64) of the aligned pairs of ``path`` ((K, 2) indices).

    a: (N, C), b: (M, C). References: Kuriyama et al. 2022, eq. 13 (||p^c_{c_i} - p^x_{x_i}||_2 per pair).
    """
    a = np.asarray(a, np.float64).reshape(len(a), -1)
    b = np.asarray(b, np.float64).reshape(len(b), -1)
    return np.linalg.norm(a[path[:, 0]] - b[path[:, 1]], axis=-1)


def dtw(a, b) -> tuple[float, np.ndarray]:
    """Exact DTW of two sequences: ``(cost, path)``.

    a: (N, C), b: (M, C) (1-D inputs are treated as C = 1). The forward pass is the jit-compiled JAX
    wavefront :func:`dtw_wavefront`, run in float64 (``jax.enable_x64`` locally, whatever the global setting)
    so that costs and tie-breaking agree with the float64 reference :func:`dtw_numpy`; lengths are padded to
    a few bucket sizes (:func:`_bucket`) so nearby lengths reuse one compilation. The path is backtracked in NumPy. ``cost`` (a
    Python float) is the accumulated cost at (N-1, M-1) = the sum of ||a_i - b_j||_2 along the returned path.
    path: (K, 2) int64, max(N, M) <= K <= N + M - 1. Not traceable itself (NumPy backtracking).

    References: Sakoe & Chiba 1978 (exact DTW); the quantity FastDTW approximates in Kuriyama et al. 2022,
    eq. 14 (docs/design.md §5: exact DTW in place of FastDTW).
    """
    a, b = _check_pair(a, b)
    n, m = len(a), len(b)
    pad = lambda x, k: np.concatenate([x, np.zeros((k - len(x), x.shape[1]))]).astype(np.float64)
    big_n, big_m = _bucket(n), _bucket(m)
    with _float64_scope():  # float64 locally: exact ties break as in the float64 reference
        cost, pred = dtw_wavefront(
            jnp.asarray(pad(a, big_n)),
            jnp.asarray(pad(b, big_m)),
            jnp.asarray(n, jnp.int32),
            jnp.asarray(m, jnp.int32),
        )
        cost, pred = float(cost), np.asarray(pred)
    return cost, _backtrack(pred, n, m)


def dtw_numpy(a, b) -> tuple[float, np.ndarray]:
    """Plain float64 NumPy reference of :func:`dtw` (row by row, same tie order); for tests, O(N M) Python.

    References: Sakoe & Chiba 1978.
    """
    a, b = _check_pair(a, b)
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    n, m = len(a), len(b)
    dist = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    choice = np.zeros((n, m), np.int8)
    for i in range(n):
        for j in range(m):
            cand = (acc[i, j], acc[i, j + 1], acc[i + 1, j])  # diag, up, left (acc is shifted by one)
            k = int(np.argmin(cand))
            choice[i, j] = k
            acc[i + 1, j + 1] = dist[i, j] + cand[k]
    i, j = n - 1, m - 1
    path = [(i, j)]
    while i > 0 or j > 0:
        di, dj = _STEP[int(choice[i, j])] if (i > 0 and j > 0) else ((1, 0) if i > 0 else (0, 1))
        i, j = i - di, j - dj
        path.append((i, j))
    return float(acc[n, m]), np.asarray(path[::-1], dtype=np.int64)

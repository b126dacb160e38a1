"""The taut string: the path of least total variation through a tube of per-frame bounds.

A one-dimensional numerical routine (no kinematics): :func:`jaxgest.motion.kinematics.floor_contact_tube`
uses it for the root height that keeps the feet within a tolerance of the floor while moving least.
"""

from __future__ import annotations

import numpy as np

__all__ = ["taut_string"]


def taut_string(lower, upper) -> np.ndarray:
    """The path ``x`` (one value per frame) of least total variation ``sum |x[t+1] - x[t]|`` with
    ``lower <= x <= upper``: the taut string through the tube (the shortest piecewise-linear path).

    ``lower``, ``upper``: ``(F,)`` bounds with ``lower <= upper``; ``-inf`` / ``+inf`` leave a frame free.
    The taut string also minimises ``sum phi(x[t+1] - x[t])`` for every convex ``phi`` among the paths in
    the tube, so it spreads the movement it cannot avoid evenly (least largest step, least squared steps).
    Free frames between bounded ones are on the straight line between them; free frames before the first
    (after the last) bounded frame keep its value; ends are free (the string leaves the first bounded frame
    level unless it must climb or fall). Where a level path fits the whole tube the level is the middle of
    the tube's common interval. Exact (a funnel walk, no iterations); the result is clipped into the bounds
    to remove rounding, so ``lower == upper`` returns ``lower`` bit for bit.
    """
    lo = np.asarray(lower, np.float64)
    hi = np.asarray(upper, np.float64)
    if lo.shape != hi.shape or lo.ndim != 1:
        raise ValueError(f"taut_string: lower {lo.shape} and upper {hi.shape} must be the same (F,) shape")
    if np.any(lo > hi):
        raise ValueError("taut_string: lower above upper on some frame")
    F = len(lo)
    bounded = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
    if F == 0:
        return lo.copy()
    if not len(bounded):
        return np.zeros(F)
    t = bounded.astype(np.float64)
    a, b = lo[bounded], hi[bounded]
    # one-sided frames: a +-inf bound is replaced by a bound far outside the data, which the string never
    # reaches (it only bends at finite bounds that constrain it)
    finite = np.concatenate([a[np.isfinite(a)], b[np.isfinite(b)]])
    big = 1e6 * (1.0 + np.abs(finite).max()) + 1e3 * (1.0 + np.ptp(finite)) * max(F, 1)
    a = np.where(np.isfinite(a), a, -big)
    b = np.where(np.isfinite(b), b, big)
    vx = _taut_vertices(t, a, b)  # list of (index into bounded, value)
    ks = np.array([k for k, _ in vx])
    vs = np.array([v for _, v in vx])
    x_b = np.interp(t, t[ks], vs)
    x = np.interp(np.arange(F, dtype=np.float64), t, x_b)  # free frames: straight lines, level at the ends
    x[bounded] = np.clip(x_b, lo[bounded], hi[bounded])
    return x


def _taut_vertices(t, a, b) -> list:
    """Vertices ``[(k, value), ...]`` of the taut string through gates ``a[k] <= x(t[k]) <= b[k]`` (``t``
    increasing), free at both ends; the first and the last gate are always vertices."""
    n = len(t)
    # free start: the string is level while the gates share an interval; it leaves that level at the gate
    # that bounds it (the last one attaining the bound) when a later gate lies wholly above or below
    top, bot, itop, ibot = b[0], a[0], 0, 0
    k = 1
    while k < n:
        if a[k] > top or b[k] < bot:
            break
        if b[k] <= top:
            top, itop = b[k], k
        if a[k] >= bot:
            bot, ibot = a[k], k
        k += 1
    if k == n:  # one level fits every gate
        level = 0.5 * (top + bot)
        return [(0, level), (n - 1, level)]
    if a[k] > top:  # must climb: start at the lowest ceiling so far
        s, xs = itop, top
    else:  # must fall
        s, xs = ibot, bot
    out = [(0, xs)] if s > 0 else []
    out.append((s, xs))
    while s < n - 1:
        U, L, iu, il = np.inf, -np.inf, s, s
        k = s + 1
        bent = False
        while k < n:
            dt = t[k] - t[s]
            u, l_ = (b[k] - xs) / dt, (a[k] - xs) / dt
            if l_ > U:  # the gate lies above every line through the funnel: bend over the ceiling at iu
                s, xs, bent = iu, b[iu], True
                break
            if u < L:  # below: bend under the floor at il
                s, xs, bent = il, a[il], True
                break
            if u <= U:
                U, iu = u, k
            if l_ >= L:
                L, il = l_, k
            k += 1
        if not bent:  # free end: the line of the funnel closest to level, bending where it must
            if L > 0:
                s, xs = il, a[il]
            elif U < 0:
                s, xs = iu, b[iu]
            else:
                out.append((n - 1, xs))
                break
        out.append((s, xs))
    return out

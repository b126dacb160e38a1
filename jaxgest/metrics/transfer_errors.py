"""Content and style errors of a style transfer (paper 000 §4.2) and the feature helpers they take.

Inputs are per-frame NumPy/JAX arrays; everything is computed in float64 NumPy except the DTW forward pass
(see :mod:`jaxgest.metrics.dtw`). Each error returns ``{"mean", "worst", "w25"}`` as Python floats.

Choices where the paper is open (docs/design.md §5), all documented in the functions:
  * exact DTW instead of FastDTW (FastDTW approximates it; its cost is never lower);
  * w25 = mean of the ceil(25 %) largest components, at least one (the authors' code takes floor(n/4),
    which is empty -- NaN -- for fewer than 4 components);
  * windows of eq. 16 are every full window k*h .. k*h+theta-1 (0-based) with k*h + theta <= F; the authors'
    code stops one hop earlier when F - theta is a multiple of h;
  * std along frames is the population std (ddof = 0), as in the authors' code;
  * the style features are velocities of the arm joints (§4.2 prose, docs/design.md, authors' code), although eq. 16
    writes hand positions;
  * D_mean / D_std are, by default (``joint_dims=3``), the sum over joints of per-joint L2 norms (docs/design.md §5
    "sum over arm joints", the authors' code), which is the scale of the paper's Table 1 (1.0-2.65 there;
    1.4 on one Bandai-Namco pair, 8 arm joints in m/s, here); ``joint_dims=None`` gives one L2 norm over all
    channels (eq. 15 as literally written);
  * ``trim`` (default 0) cuts frames at both ends; the authors' code cuts 60 frames (1 s at 60 fps).
    :mod:`jaxgest.tgst.evaluate` applies its protocol (trim, root-local positions, forward differences,
    mirrored style) to the features before calling these functions.

References: Kuriyama et al. 2022, §4.2, eqs. 13-16.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.metrics.dtw import dtw, path_distances
from jaxgest.motion import kinematics


def _as_frames(x, name: str, channels: int | None = None) -> np.ndarray:
    x = np.asarray(x, np.float64)
    if x.ndim != 2 or (channels is not None and x.shape[1] != channels):
        want = f"(frames, {channels})" if channels is not None else "(frames, channels)"
        raise DataError(f"{name}: expected shape {want}, got {x.shape}")
    if len(x) == 0:
        raise DataError(f"{name}: no frames")
    if not np.all(np.isfinite(x)):
        raise DataError(f"{name}: contains NaN or inf")
    return x


def _trim(x: np.ndarray, trim: int, name: str) -> np.ndarray:
    if trim < 0:
        raise DataError(f"{name}: trim must be >= 0, got {trim}")
    if trim == 0:
        return x
    if len(x) <= 2 * trim:
        raise DataError(f"{name}: {len(x)} frames is too short to cut {trim} frames at both ends")
    return x[trim:-trim]


def summarize_errors(components) -> dict:
    """``{"mean", "worst", "w25"}`` of error components ``(K,)``.

    mean = average, worst = maximum, w25 = mean of the ceil(K / 4) largest components (at least one, so
    it is defined for any K >= 1; the authors' code uses floor(K / 4), which differs when 4 does not divide K).
    References: Kuriyama et al. 2022, §4.2 ("mean", "worst-case", "mean of the first 25 % most significant").
    """
    e = np.asarray(components, np.float64).reshape(-1)
    if e.size == 0:
        raise DataError("error summary: no error components")
    k = max(1, math.ceil(0.25 * e.size))
    worst_first = np.sort(e)[::-1]
    return {"mean": float(np.mean(e)), "worst": float(worst_first[0]), "w25": float(np.mean(worst_first[:k]))}


def content_error_components(content_hands, transfer_hands) -> np.ndarray:
    """E_i^content = ||p^c_{c_i} - p^x_{x_i}||_2 over the DTW-aligned pairs I = DTW(p^c, p^x); ``(K,)``.

    content_hands: (Fc, 6), transfer_hands: (Fx, 6) -- both hands' positions in metres (world or root-local,
    one protocol for both).
    References: Kuriyama et al. 2022, eqs. 13-14 (exact DTW in place of FastDTW, docs/design.md §5).
    """
    pc = _as_frames(content_hands, "content_error: content_hands", 6)
    px = _as_frames(transfer_hands, "content_error: transfer_hands", 6)
    _, path = dtw(pc, px)
    return path_distances(pc, px, path)


def content_error(content_hands, transfer_hands, *, trim: int = 0) -> dict:
    """Content error of a transfer: ``{"mean", "worst", "w25"}`` of eq. 13 over the DTW path of eq. 14.

    content_hands: (Fc, 6) and transfer_hands: (Fx, 6) are both hands' positions IN METRES (world or
    root-local; [left xyz, right xyz]; callers convert, e.g. :func:`hands_metres` for centimetre BVH files). The clips are
    aligned by exact DTW (Euclidean frame distance, steps (1,1), (1,0), (0,1)); every aligned pair is one
    component. ``trim`` cuts that many frames at both ends of both clips first (default 0; the authors' code
    cuts 60 frames of the transferred clip). Statistics as in :func:`summarize_errors`.

    References: Kuriyama et al. 2022, eqs. 13-14 and §4.2 (mean / worst / worst 25 %).
    """
    pc = _trim(
        _as_frames(content_hands, "content_error: content_hands", 6), trim, "content_error: content_hands"
    )
    px = _trim(
        _as_frames(transfer_hands, "content_error: transfer_hands", 6), trim, "content_error: transfer_hands"
    )
    return summarize_errors(content_error_components(pc, px))


def window_for_fps(fps: float, theta_at_60: int = 128) -> int:
    """Style window theta scaled with the frame rate: round(theta_at_60 * fps / 60) (halves round up).

    References: Kuriyama et al. 2022, §4.2 (theta = 128 at 60 fps); docs/design.md §5 (scale theta with the rate).
    """
    if not fps > 0 or theta_at_60 < 1:
        raise DataError(f"window_for_fps: need fps > 0 and theta_at_60 >= 1, got {fps} and {theta_at_60}")
    return max(1, math.floor(theta_at_60 * fps / 60.0 + 0.5))


def window_statistics(features, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std along frames of every half-overlapped window rho_k; ``(F, C) -> ((K, C), (K, C))``.

    Window k covers frames k*h .. k*h + theta - 1 (0-based) with h = floor(theta / 2) and k*h + theta <= F,
    so K = (F - theta) // h + 1. std is the population std (ddof = 0). Needs F >= theta (else DataError).
    References: Kuriyama et al. 2022, eq. 16.
    """
    x = _as_frames(features, "style windows")
    if window < 1:
        raise DataError(f"style_error: window must be >= 1 frame, got {window}")
    if len(x) < window:
        raise DataError(f"style_error: clip of {len(x)} frames is shorter than one window of {window} frames")
    hop = max(1, window // 2)
    starts = np.arange(0, len(x) - window + 1, hop)
    segs = x[starts[:, None] + np.arange(window)[None, :]]  # (K, theta, C)
    return segs.mean(axis=1), segs.std(axis=1)


def _group_norm(diff: np.ndarray, joint_dims: int | None) -> np.ndarray:
    """L2 norm over the last axis, or the sum of per-joint L2 norms over groups of ``joint_dims`` channels."""
    if joint_dims is None:
        return np.linalg.norm(diff, axis=-1)
    if diff.shape[-1] % joint_dims:
        raise DataError(f"style_error: {diff.shape[-1]} channels do not split into joints of {joint_dims}")
    per_joint = diff.reshape(*diff.shape[:-1], -1, joint_dims)
    return np.linalg.norm(per_joint, axis=-1).sum(axis=-1)


def style_error_components(transfer_vel, style_vel, window: int, *, joint_dims: int | None = 3) -> np.ndarray:
    """E_k^style = min_j D_mean(rho^x_k, rho^s_j) + D_std(rho^x_k, rho^s_j) for every transfer window k; ``(K,)``.

    D_mean / D_std: the sum over joints of per-joint L2 norms of the difference of the window means / stds
    (``joint_dims=3``, default: docs/design.md §5 and the authors' code), or one L2 norm over all channels
    (``joint_dims=None``, eq. 15 as literally written).
    References: Kuriyama et al. 2022, eqs. 15-16.
    """
    xm, xs = window_statistics(transfer_vel, window)
    sm, ss = window_statistics(style_vel, window)
    if xm.shape[1] != sm.shape[1]:
        raise DataError(f"style_error: transfer has {xm.shape[1]} channels but style has {sm.shape[1]}")
    d = _group_norm(xm[:, None] - sm[None], joint_dims) + _group_norm(xs[:, None] - ss[None], joint_dims)
    return d.min(axis=1)


def style_error(transfer_vel, style_vel, window: int, *, trim: int = 0, joint_dims: int | None = 3) -> dict:
    """Style error of a transfer: ``{"mean", "worst", "w25"}`` of eq. 15 over the windows of eq. 16.

    transfer_vel: (Fx, C), style_vel: (Fs, C) per-frame features -- the velocities (per second, e.g. m/s) of
    the arm joints, see :func:`arm_velocities`; the caller computes them (eq. 16 writes hand positions, §4.2
    prose, docs/design.md §5 and the authors' code use arm-joint velocities). window: theta in frames
    (:func:`window_for_fps`; 128 at 60 fps), hop floor(theta / 2). ``trim`` cuts that many frames at both ends
    of both inputs first (default 0; the authors' code cuts 60 at 60 fps). ``joint_dims``: 3 (default) -> sum over
    joints of per-joint norms (docs/design.md §5 "sum over arm joints", authors' code); None -> one L2 norm over all C
    channels (eq. 15 as literally written). Clips shorter than one window (after trimming) raise DataError.

    References: Kuriyama et al. 2022, eqs. 15-16 and §4.2 (mean / worst / worst 25 %).
    """
    x = _trim(_as_frames(transfer_vel, "style_error: transfer_vel"), trim, "style_error: transfer_vel")
    s = _trim(_as_frames(style_vel, "style_error: style_vel"), trim, "style_error: style_vel")
    return summarize_errors(style_error_components(x, s, window, joint_dims=joint_dims))


def _world(world_positions, name: str) -> np.ndarray:
    p = np.asarray(world_positions, np.float64)
    if p.ndim != 3 or p.shape[-1] != 3:
        raise DataError(f"{name}: expected joint positions (frames, joints, 3), got {p.shape}")
    return p


def arm_velocities(
    world_positions, fps: float, joint_indices: Sequence[int], *, scale: float = 1.0, forward: bool = False
) -> np.ndarray:
    """Per-second velocities of the chosen joints, flattened: ``(F, J, 3) -> (F', 3 * len(joint_indices))``.

    ``forward=True`` (the authors' protocol): the F' = F - 1 forward differences
    v_t = (p_{t+1} - p_t) * fps (:func:`jaxgest.motion.kinematics.forward_differences`; the authors' code
    takes 60 * frame differences at 60 fps). ``forward=False`` (the world protocol, as before): F' = F
    backward differences with frame 0 repeating frame 1 (:func:`jaxgest.motion.kinematics.joint_velocities`),
    so a first-frame spike enters twice. Joints in ``joint_indices`` order (channels [j0 xyz, j1 xyz, ...]),
    times ``scale`` (0.01 for centimetres -> metres per second). Positions may be world or root-local.
    References: Kuriyama et al. 2022, §4.2 (velocities of the arm joints); the authors' evaluator.py.
    """
    p = _world(world_positions, "arm_velocities")
    if len(p) < 2:
        raise DataError(f"arm_velocities: need at least 2 frames, got {len(p)}")
    idx = np.asarray(joint_indices, np.int64)
    diff = kinematics.forward_differences if forward else kinematics.joint_velocities
    v = diff(p[:, idx], float(fps)) * float(scale)
    return v.reshape(len(v), -1)


def hands_metres(world_positions_cm, hand_indices: Sequence[int]) -> np.ndarray:
    """Both hands' positions in metres (world or root-local): ``(F, J, 3)`` centimetres -> ``(F, 6)`` = [left xyz, right xyz].

    hand_indices: (left, right) joint indices. References: Kuriyama et al. 2022, §4.2 (p^l: 6-D hand
    positions in metres).
    """
    p = _world(world_positions_cm, "hands_metres")
    idx = np.asarray(hand_indices, np.int64)
    if idx.shape != (2,):
        raise DataError(f"hands_metres: expected two hand indices, got {list(idx)}")
    return (p[:, idx] * 0.01).reshape(len(p), 6)

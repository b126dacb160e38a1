"""The root joint: root-yaw removal/restoration, root position, floor contact (docs/design.md §2).

Motion-level functions in NumPy float64 on top of :mod:`jaxgest.motion.kinematics` (which re-exports them).
References: Kuriyama et al. 2022, §3.1 (root orientation and floor contact).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.motion import rotations as R
from jaxgest.motion.kinematics import (  # noqa: F401 (_hips_index re-exported)
    _hips_index, _root_and_parent, forward_kinematics, global_rotations, global_transforms)
from jaxgest.motion.skeleton import Motion, Skeleton
from jaxgest.motion.taut_string import taut_string

# Root yaw

def _up_vector(up_axis: int) -> np.ndarray:
    u = np.zeros(3)
    u[up_axis] = 1.0
    return u


def swing_twist(q: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Decompose ``q = swing * twist`` with ``twist`` a rotation about ``axis`` (unit vector)."""
    q = np.asarray(q, np.float64)
    proj = np.sum(q[..., 1:] * axis, axis=-1, keepdims=True) * axis
    twist = np.concatenate([q[..., :1], proj], axis=-1)
    n = np.linalg.norm(twist, axis=-1, keepdims=True)
    ident = np.zeros_like(twist)
    ident[..., 0] = 1.0
    twist = np.where(n > 1e-12, twist / np.maximum(n, 1e-12), ident)
    swing = R.quat_mul(q, R.quat_inv(twist))
    return swing, twist


def remove_root_yaw(motion: Motion, root: str | None = None) -> tuple[Motion, np.ndarray]:
    """Remove the rotation about the vertical axis from the root joint's *global* rotation.

    The hips' world rotation is split (swing-twist about the skeleton's up axis, on the world side)
    as ``G = T_yaw * G'`` with ``T_yaw`` a rotation about up and ``G'`` free of any rotation about up;
    the returned motion has ``G'`` (its local rotation adjusted through a static parent such as
    Bandai-Namco's ``joint_Root``) and the root's world position turned by ``T_yaw^-1`` about the vertical
    axis through the world origin, so the whole body (and its path) is turned together.

    Facing: ``T_yaw`` is the heading of the hips measured from their T-pose/rest facing, which is +Z for
    both datasets (Bandai-Namco hips frame X->+Y, Y->-X, Z->+Z; ZEGGS hips frame = world); for upright
    hips it turns the rest forward (+Z) onto the hips' horizontal forward direction, so a yaw-free motion
    faces +Z. ``root=None`` picks the hips (the first joint below the file root with several children,
    i.e. ``Hips`` for both datasets). Returns ``(motion, yaw (F, 4))``; :func:`restore_root_yaw` inverts it.

    References: Kuriyama et al. 2022, §3.1 (root orientation: the vertical component is cancelled
    before encoding and copied back from the content after transfer).
    """
    sk = motion.skeleton
    r, p = _root_and_parent(sk, root)
    up = _up_vector(sk.up_axis)
    grot = global_rotations(motion)
    g_root = grot[:, r]
    # World-frame decomposition: G = T * S with T about up  <=>  G^-1 = S^-1 T^-1; use swing_twist on G^-1.
    swing_inv, twist_inv = swing_twist(R.quat_inv(g_root), up)
    yaw = R.quat_inv(twist_inv)
    new_global = R.quat_mul(R.quat_inv(yaw), g_root)
    new = _set_root_global(motion, r, p, grot, new_global, R.quat_inv(yaw))
    return new, R.quat_canonicalize(yaw)


def restore_root_yaw(motion: Motion, yaw: np.ndarray, root: str | None = None) -> Motion:
    """Inverse of :func:`remove_root_yaw`: turn the root (rotation and horizontal translation) by ``yaw``."""
    sk = motion.skeleton
    r, p = _root_and_parent(sk, root)
    grot = global_rotations(motion)
    new_global = R.quat_mul(yaw, grot[:, r])
    return _set_root_global(motion, r, p, grot, new_global, np.asarray(yaw, np.float64))


def _set_root_global(motion, r, p, grot, new_global, turn):
    rot = motion.rotations.copy()
    trans = motion.translations.copy()
    parent_global = grot[:, p] if p >= 0 else None
    if parent_global is None:
        rot[:, r] = new_global
        trans[:, r] = R.quat_rotate(turn, trans[:, r])
    else:
        rot[:, r] = R.quat_mul(R.quat_inv(parent_global), new_global)
        # Turn the root's world position about the vertical axis through the parent's origin.
        world = R.quat_rotate(parent_global, trans[:, r])
        trans[:, r] = R.quat_rotate(R.quat_inv(parent_global), R.quat_rotate(turn, world))
    return motion.replace(rotations=R.quat_canonicalize(rot), translations=trans)


def set_root_position(motion: Motion, position: np.ndarray, root: str | None = None) -> Motion:
    """Move the root joint (the hips by default) so its world position is ``position`` (F, 3) per frame.

    Only the root's local translation changes (expressed through a static parent such as ``joint_Root``).
    """
    sk = motion.skeleton
    r, p = _root_and_parent(sk, root)
    position = np.broadcast_to(np.asarray(position, np.float64), (motion.num_frames, 3))
    trans = motion.translations.copy()
    if p < 0:
        trans[:, r] = position
    else:
        grot, gpos = global_transforms(motion)
        trans[:, r] = R.quat_rotate(R.quat_inv(grot[:, p]), position - gpos[:, p])
    return motion.replace(translations=trans)


# ---------------------------------------------------------------------------------------------------
# Floor contact

FOOT_HINTS = ("toe", "foot", "ankle")


def foot_joints(skeleton: Skeleton) -> list[int]:
    """Indices of foot and toe joints (names containing toe/foot/ankle), End Sites excluded."""
    return [i for i, n in enumerate(skeleton.names) if any(h in n.lower() for h in FOOT_HINTS)]


def lowest_foot_height(motion: Motion, feet: Sequence[str] | None = None) -> np.ndarray:
    """Height ``(F,)`` of the lowest foot/toe joint per frame (file units, the skeleton's up axis)."""
    sk = motion.skeleton
    idx = [sk.index(n) for n in feet] if feet else foot_joints(sk)
    if not idx:
        raise DataError(f"skeleton {', '.join(sk.names[:4])}, ... has no foot/toe joints to put on the floor")
    return forward_kinematics(motion)[:, idx, sk.up_axis].min(axis=1)


def floor_contact(motion: Motion, feet: Sequence[str] | None = None, root: str | None = None,
                  height=0.0) -> Motion:
    """Set the root's height per frame so the lowest foot/toe joint is at ``height`` (default the floor, 0).

    ``height``: a number or ``(F,)`` per-frame heights, e.g. :func:`lowest_foot_height` of the clip a
    transfer performs, so the result keeps that clip's contact height (a foot joint of a standing
    Bandai-Namco actor sits 4.25 cm above the floor) and its jumps. Only the root's vertical
    coordinate changes.
    References: Kuriyama et al. 2022, §3.1 ("determines the root position at each frame to fix the lower
    foot position on a floor level, using forward kinematics").
    """
    lowest = lowest_foot_height(motion, feet)  # (F,)
    target = np.broadcast_to(np.asarray(height, np.float64), lowest.shape)
    return shift_root_height(motion, target - lowest, root)


def shift_root_height(motion: Motion, shift, root: str | None = None) -> Motion:
    """Move the root (hence every joint) vertically by ``shift`` (a number or ``(F,)``, file units).

    Only the root's vertical world coordinate changes: the shift is expressed in the root's parent frame
    when the root has a parent (e.g. a static ``joint_Root``).
    """
    sk = motion.skeleton
    r, p = _root_and_parent(sk, root)
    d = np.zeros((motion.num_frames, 3))
    d[:, sk.up_axis] = np.broadcast_to(np.asarray(shift, np.float64), (motion.num_frames,))
    trans = motion.translations.copy()
    if p >= 0:
        grot = global_rotations(motion)
        d = R.quat_rotate(R.quat_inv(grot[:, p]), d)
    trans[:, r] += d
    return motion.replace(translations=trans)


def floor_contact_tube(motion: Motion, feet: Sequence[str] | None = None, root: str | None = None,
                       height=0.0, tolerance: float = 0.0, contact=None) -> Motion:
    """:func:`floor_contact` that moves the root least: the root's vertical shift keeps the lowest foot/toe
    joint within ``tolerance`` of ``height`` on the ``contact`` frames and is otherwise free, and of those
    shift paths the one of least total variation (:func:`taut_string`) is applied.

    ``height``: as :func:`floor_contact` (a number or ``(F,)``). ``tolerance``: file units (cm on the
    Bandai-Namco and ZEGGS rigs), >= 0. ``contact``: ``(F,)`` bools, the frames held to the floor (default
    every frame). With ``tolerance=0`` and every frame in contact this is :func:`floor_contact` exactly.
    Why: the per-frame contact sets the root height from the feet on every frame, so every frame-to-frame
    error of the legs (e.g. legs decoded from upper-body latents, Kuriyama et al. §3.1) becomes vertical
    motion of the whole body; inside the tolerance the taut string keeps the root still where it can and
    spreads the movement it must make (experiments/tgst_bandai/README.md, section 2c).
    References: Kuriyama et al. 2022, §3.1 ("determines the root position at each frame to fix the lower
    foot position on a floor level, using forward kinematics"). Difference: on contact frames the lowest
    foot is within ``tolerance`` of the floor level, not on it; frames outside ``contact`` (the content's
    flight phases) are not fixed to it.
    """
    if not tolerance >= 0:
        raise ValueError(f"floor_contact_tube: tolerance must be >= 0, got {tolerance}")
    lowest = lowest_foot_height(motion, feet)  # (F,)
    s = np.broadcast_to(np.asarray(height, np.float64), lowest.shape) - lowest  # the per-frame shift
    on = np.ones(len(s), bool) if contact is None else np.asarray(contact, bool)
    if on.shape != s.shape:
        raise ValueError(f"floor_contact_tube: contact has shape {on.shape}, expected {s.shape}")
    lo = np.where(on, s - tolerance, -np.inf)
    hi = np.where(on, s + tolerance, np.inf)
    return shift_root_height(motion, taut_string(lo, hi), root)

"""Forward kinematics, mirroring, root-yaw removal/restoration, floor contact, velocities (SPEC §2).

Also the pieces of the authors' evaluation protocol (SPEC §5): :func:`root_local_positions` (root at the
origin, root rotation reset), :func:`forward_differences` and :func:`append_motion` (the mirrored style clip
appended with a short slerp transition).

Motion-level functions take and return :class:`~jaxgest.motion.skeleton.Motion` and compute in NumPy
float64 (exact file-level numbers). :func:`fk_positions` is the batched ``jax.numpy`` version for use
inside jit (losses, features); its parent array is static.
"""

from __future__ import annotations

import functools
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.errors import DataError
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton, mirror_pairs, mirror_partner  # noqa: F401 (re-exported)
from jaxgest.motion.taut_string import taut_string  # noqa: F401 (re-exported; floor_contact_tube's solver)


# ---------------------------------------------------------------------------------------------------
# Forward kinematics


def global_transforms(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """World rotations ``(F, J, 4)`` and positions ``(F, J, 3)`` of every joint, file order, file units.

    ``G_j = G_parent(j) * q_j`` and ``p_j = p_parent(j) + G_parent(j) t_j`` where ``t_j`` is the joint's
    local translation (position channels or rest offset).
    """
    parents = motion.skeleton.parents
    F, J = motion.rotations.shape[:2]
    grot = np.empty((F, J, 4))
    gpos = np.empty((F, J, 3))
    for j in range(J):
        p = parents[j]
        if p < 0:
            grot[:, j] = motion.rotations[:, j]
            gpos[:, j] = motion.translations[:, j]
        else:
            grot[:, j] = R.quat_mul(grot[:, p], motion.rotations[:, j])
            gpos[:, j] = gpos[:, p] + R.quat_rotate(grot[:, p], motion.translations[:, j])
    return grot, gpos


def forward_kinematics(motion: Motion) -> np.ndarray:
    """World positions ``(F, J, 3)`` of all J joints in file order (End Sites excluded), file units."""
    return global_transforms(motion)[1]


def global_rotations(motion: Motion) -> np.ndarray:
    """World rotations ``(F, J, 4)`` (w, x, y, z) of all joints in file order."""
    return global_transforms(motion)[0]


def root_local_positions(motion: Motion, root: str | None = None) -> np.ndarray:
    """Joint positions ``(F, J, 3)`` with the root at the origin and its rotation reset (file units).

    ``p'_j = G_root^-1 (p_j - p_root)``: forward kinematics with the root's translation zeroed and its world
    rotation set to the identity, i.e. every joint in the frame of the root. The root is the hips (the first
    joint below the file root with several children: ``Hips`` of Bandai-Namco, below its static
    ``joint_Root``, and of ZEGGS) unless ``root`` names another joint. Joints above the root get the same
    transform (they are static wrappers on both datasets).
    References: the authors' evaluator (``get_joint_positions(root_positions=None)`` in dataset/mocap.py:
    "We also reset orientation of root"); SPEC §5 (authors' protocol).
    """
    r, _ = _root_and_parent(motion.skeleton, root)
    grot, gpos = global_transforms(motion)
    inv = R.quat_inv(grot[:, r])[:, None, :]
    return R.quat_rotate(np.broadcast_to(inv, grot.shape), gpos - gpos[:, r : r + 1])


def fk_positions(rotations: jax.Array, translations: jax.Array, parents: Sequence[int]) -> jax.Array:
    """Batched jnp forward kinematics: ``(..., J, 4)``, ``(..., J, 3)`` -> world positions ``(..., J, 3)``.

    Same equations as :func:`global_transforms`. ``parents`` is static (a Python sequence, -1 for roots);
    joints are processed one tree *level* at a time (all joints of equal depth in one vectorised step), so
    the traced graph has depth-many steps (7 for the body, 12 for ZEGGS) instead of one per joint, which
    keeps jit compile times small. Usable inside jit and under grad.
    """
    levels, where = _fk_levels(tuple(int(p) for p in parents))
    grot = rotations[..., levels[0][0], :]
    gpos = translations[..., levels[0][0], :]
    out = [gpos]
    for idx, par in levels[1:]:
        gp, pp = grot[..., par, :], gpos[..., par, :]
        grot = R.quat_mul(gp, rotations[..., idx, :])
        gpos = pp + R.quat_rotate(gp, translations[..., idx, :])
        out.append(gpos)
    return jnp.concatenate(out, axis=-2)[..., where, :]


@functools.lru_cache(maxsize=64)
def _fk_levels(parents: tuple) -> tuple[tuple, np.ndarray]:
    """Joints grouped by depth: ``((indices, parent positions within the previous level), ...)`` and the
    permutation from level order back to file order (memoised; every array read-only)."""
    depth = []
    for j, p in enumerate(parents):
        if p >= j:
            raise ValueError(f"parents must precede children (joint {j} has parent {p})")
        depth.append(0 if p < 0 else depth[p] + 1)
    depth = np.asarray(depth)
    levels, pos = [], {}
    for d in range(int(depth.max()) + 1):
        idx = np.flatnonzero(depth == d)
        par = np.array([pos[parents[j]] for j in idx]) if d else np.zeros(0, np.int64)
        levels.append((idx, par))
        pos = {int(j): i for i, j in enumerate(idx)}
    order = np.concatenate([idx for idx, _ in levels])
    inverse = np.argsort(order)
    for arr in [inverse, *(a for level in levels for a in level)]:
        arr.flags.writeable = False  # memoised and shared by every caller: read-only
    return tuple(levels), inverse


def joint_velocities(positions: np.ndarray, fps: float) -> np.ndarray:
    """Per-second joint velocities ``(F, ..., 3)`` by backward differences; frame 0 repeats frame 1."""
    positions = np.asarray(positions, np.float64)
    v = np.empty_like(positions)
    if len(positions) < 2:
        v[:] = 0.0
        return v
    v[1:] = (positions[1:] - positions[:-1]) * fps
    v[0] = v[1]
    return v


def forward_differences(positions: np.ndarray, fps: float) -> np.ndarray:
    """Per-second velocities ``(F - 1, ..., 3)``: ``v_t = (p_{t+1} - p_t) * fps`` for t = 0 .. F - 2.

    No frame is repeated or invented (unlike :func:`joint_velocities`), so every velocity is the exact
    displacement of one frame step: a constant-speed motion gives that speed at both ends.
    References: the authors' evaluator (``60. * (x[1:] - x[:-1])`` in evaluator.py); SPEC §5.
    """
    positions = np.asarray(positions, np.float64)
    if len(positions) < 2:
        raise DataError(f"forward differences need at least 2 frames, got {len(positions)}")
    return (positions[1:] - positions[:-1]) * float(fps)


def append_motion(first: Motion, second: Motion, transition: int = 0) -> Motion:
    """``first`` followed by ``second`` (same skeleton and rate), blended over ``transition`` frames.

    The last ``transition`` frames of ``first`` move linearly toward the first ``transition`` frames of
    ``second`` (slerp of rotations, lerp of translations, weight k / transition at the k-th of them), then
    ``second`` continues from its frame ``transition``: ``Fa + Fb - transition`` frames. ``transition`` is
    clamped to both lengths. Used to append the mirrored style clip as the authors' evaluator does
    (``MocapClip.append(mirrored, transit=True, period=30)`` at 60 fps).
    References: the authors' dataset/mocap.py (``add_mirror_motion``, ``append``); SPEC §5.
    """
    if first.skeleton.num_joints != second.skeleton.num_joints:
        raise DataError("append_motion: the clips have different skeletons")
    n = max(0, min(int(transition), first.num_frames, second.num_frames))
    rot_a, tr_a = first.rotations.copy(), first.translations.copy()
    if n:
        w = (np.arange(n) / n)[:, None]
        a_idx = slice(first.num_frames - n, first.num_frames)
        q_a, q_b = rot_a[a_idx], second.rotations[:n]
        rot_a[a_idx] = R.quat_slerp(q_a, q_b, np.broadcast_to(w, q_a.shape[:2]))
        tr_a[a_idx] = (1.0 - w[..., None]) * tr_a[a_idx] + w[..., None] * second.translations[:n]
    return first.replace(
        rotations=np.concatenate([rot_a, second.rotations[n:]]),
        translations=np.concatenate([tr_a, second.translations[n:]]),
    )


# ---------------------------------------------------------------------------------------------------
# Mirroring

def _reflection(axis: int) -> np.ndarray:
    m = np.eye(3)
    m[axis, axis] = -1.0
    return m


def mirror_frames(skeleton: Skeleton, axis: int = 0, tpose: np.ndarray | None = None) -> np.ndarray:
    """Per-joint reflections ``M_j`` (J, 3, 3): the world reflection ``S`` seen from joint j's frame.

    A mirrored pose has world rotations ``G'_j = S G_perm(j) M_j`` (:func:`mirror`). ``M_j`` maps joint j's
    local axes onto its partner's, and the choice matters: every valid ``M_j`` gives the same world
    positions, but only the right one keeps a mirrored clip's LOCAL rotations where the originals' are.

    * ``tpose`` given (``(J, 4)`` world rotations of the rig in a left/right-symmetric reference posture,
      e.g. its T-pose, :func:`jaxgest.motion.body.tpose_globals`): ``M_j = T_perm(j)^T S T_j``. The
      reference posture then mirrors onto itself (every local rotation unchanged), so mirrored local
      rotations have the distribution of the originals'. This is the only correct choice on rigs whose
      identity pose is not symmetric, such as Bandai-Namco (its right arm and leg frames are the left ones
      turned by 180 deg about the bone; only the T-pose tells).
    * ``tpose`` None: inferred from the rest offsets: the axis reflection that maps the offsets of joint
      j's children onto their partners' offsets (``o_perm(c) ~= M_j o_c``), ties (a single child along an
      axis) and childless joints resolved to the parent's reflection, the world frame (parent of the root)
      using ``S``. Right for rigs whose identity pose is symmetric with world-aligned frames (ZEGGS: every
      ``M_j = S``, the authors' quaternion conjugation), and positions are exact on any rig; on
      Bandai-Namco it leaves the shoulders, arms and legs 180 deg off (pass its T-pose).
    """
    perm = mirror_pairs(skeleton)
    J = skeleton.num_joints
    world = _reflection(axis)
    if tpose is not None:
        t = np.asarray(tpose, np.float64)
        if t.shape != (J, 4):
            raise ValueError(f"mirror_frames: tpose has shape {t.shape}, expected ({J}, 4)")
        tm = R.quat_to_matrix(t / np.linalg.norm(t, axis=-1, keepdims=True))
        return np.einsum("jba,bc,jcd->jad", tm[perm], world, tm)
    parents = skeleton.parents
    frames = np.empty((J, 3, 3))
    cands = [_reflection(a) for a in range(3)]
    for j in range(J):
        parent_frame = world if parents[j] < 0 else frames[parents[j]]
        kids = [c for c in np.flatnonzero(parents == j) if np.linalg.norm(skeleton.offsets[c]) > 1e-6]
        if not kids:
            frames[j] = parent_frame
            continue
        src = skeleton.offsets[kids]
        dst = skeleton.offsets[perm[kids]]
        errs = np.array([np.abs(src @ m.T - dst).sum() for m in cands])
        best = np.flatnonzero(errs <= errs.min() + 1e-6 * (1.0 + np.abs(src).sum()))
        inherit = [int(b) for b in best if np.array_equal(cands[b], parent_frame)]
        frames[j] = cands[inherit[0] if inherit else int(best[0])]
    return frames


def mirror(motion: Motion, axis: int = 0, keep_rig_offsets: bool = True,
           tpose: np.ndarray | None = None) -> Motion:
    """Mirror a motion about the sagittal plane (world normal ``axis``, X by default), swapping L/R joints.

    With ``S`` the world reflection and ``M_j`` the per-joint reflections of :func:`mirror_frames`, world
    rotations become ``G'_j = S G_perm(j) M_j`` and world positions ``p'_j = S p_perm(j)`` exactly, i.e.
    local rotations ``q'_j = M_parent^T q_perm(j) M_j`` and local translations
    ``t'_j = M_parent^T t_perm(j)``. Applying it twice is the identity (to rounding). L/R pairs come from
    joint names (:func:`jaxgest.motion.skeleton.mirror_pairs`).

    Representation: pass the rig's T-pose (``tpose``, world rotations ``(J, 4)``) to get local rotations
    distributed like the originals' (a symmetric pose mirrors onto itself); without it the reflections are
    inferred from the rest offsets, which is right on rigs with a symmetric identity pose (ZEGGS) but not on
    Bandai-Namco (see :func:`mirror_frames`). World positions are the same either way.

    Bone lengths: a rig is rarely exactly symmetric. With ``keep_rig_offsets`` (default) joints without
    BVH position channels keep their own local translations (the rig's bone lengths), so the result is a
    valid pose of the rig that survives saving; world positions are then the reflection up to the rig's
    L/R asymmetry (ZEGGS: up to 3.6 cm at the fingertips; its left and right arm bones differ in length).
    Joints with position channels (the root; every joint of Bandai-Namco) are always mirrored exactly, so
    on Bandai-Namco world positions are reflected to rounding (its rest skeleton is itself symmetric to
    0.05 cm: ``LowerLeg_R`` has z = -0.04). With ``keep_rig_offsets=False`` world positions are reflected
    exactly on any rig, with local translations that may leave the rig's offsets.

    Args:
      motion: any Motion.
      axis: world axis normal to the sagittal plane (0 = X, the left-right axis of both datasets).
      keep_rig_offsets: see above.
      tpose: optional ``(J, 4)`` world rotations of the rig in a symmetric reference posture (T-pose).

    References: the authors' dataset/mocap.py ``add_mirror_motion`` (swap L/R, negate the quaternions' y and
    z, negate x of the root position: ``M_j = S`` on every joint, i.e. their rig's identity pose is
    symmetric); Kuriyama et al. 2022, §4.1 (mirrored style as augmentation).
    """
    sk = motion.skeleton
    perm = mirror_pairs(sk)
    frames = mirror_frames(sk, axis, tpose)
    world = _reflection(axis)
    mats = R.quat_to_matrix(motion.rotations)  # (F, J, 3, 3)
    new_m = np.empty_like(mats)
    new_t = np.empty_like(motion.translations)
    for j in range(sk.num_joints):
        p = sk.parents[j]
        mp = world if p < 0 else frames[p]
        new_m[:, j] = mp.T @ mats[:, perm[j]] @ frames[j]
        has_position = any(c.endswith("position") for c in sk.channels[j])
        if keep_rig_offsets and not has_position:
            new_t[:, j] = motion.translations[:, j]
        else:
            new_t[:, j] = motion.translations[:, perm[j]] @ mp
    return motion.replace(rotations=R.matrix_to_quat(new_m), translations=new_t)


# ---------------------------------------------------------------------------------------------------
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


def _root_and_parent(skeleton: Skeleton, root: str | None):
    if root is None:
        root_idx = _hips_index(skeleton)
    else:
        root_idx = skeleton.index(root)
    return root_idx, int(skeleton.parents[root_idx])


def _hips_index(skeleton: Skeleton) -> int:
    """The hips: the first joint from the file root with more than one child (skips static wrappers)."""
    j = int(np.flatnonzero(skeleton.parents < 0)[0])
    while True:
        kids = np.flatnonzero(skeleton.parents == j)
        if len(kids) != 1:
            return j
        j = int(kids[0])


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

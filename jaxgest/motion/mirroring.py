"""Mirroring a motion about the sagittal plane, swapping left and right joints (docs/design.md §2).

:func:`mirror_frames` gives the per-joint reflections, :func:`mirror` applies them to a
:class:`~jaxgest.motion.skeleton.Motion` (NumPy float64). Re-exported by :mod:`jaxgest.motion.kinematics`.
"""

from __future__ import annotations

import numpy as np

from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton, mirror_pairs


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

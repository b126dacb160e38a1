"""ZeroEGGS motion features: the pose vector ``a`` / pose state ``y`` (paper 001 §3.2-3.3, docs/design.md §2).

Per frame, for ``j`` joints (layout :class:`PoseLayout`, size ``15 j + 6``)::

    [ rho_p (3j) | rho_r (6j) | drho_p (3j) | drho_r (3j) | dr_p (3) | dr_r (3) ]

* ``rho_p``  joint positions in the character-root frame (cm),
* ``rho_r``  joint rotations in the character-root frame as 2-axis (6-D) matrices,
* ``drho_p`` joint translational velocities in the root frame (cm/s),
* ``drho_r`` joint rotational velocities in the root frame, scaled angle-axis (rad/s),
* ``dr_p``   root translational velocity in the root frame (cm/s),
* ``dr_r``   root rotational velocity in the root frame, scaled angle-axis (rad/s; only the yaw part is
  non-zero because the root is a ground-plane transform).

The character root is a ground-plane transform: its position is the world position of the second spine
joint projected on the ground; its orientation is the yaw that turns the world forward axis onto the hips'
forward direction projected on the ground. The paper uses "the z-axis of the hip joint"; that axis is a
property of the ZEGGS rig only, so for any skeleton we define the hips' forward direction as
``cross(up, left_hip - right_hip)`` (lateral vector of the two upper legs) -- on the ZEGGS rig this is the
hip z-axis up to the rig's own small tilt. A skeleton without L/R upper legs falls back to the root joint's
z-axis, as in the paper.

Velocities are backward differences times fps; frame 0 repeats frame 1's velocity so the feature sequence
keeps F frames.

References: Ghorbani et al. 2023, §3.2 (feature vector a) and §3.3 (pose state y); Zhang et al. 2018
(scaled angle-axis velocities); Zhou et al. 2019 (6-D rotations).
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.motion import rotations
from jaxgest.motion.skeleton import Motion, Skeleton


@dataclasses.dataclass(frozen=True)
class PoseLayout:
    """Slices of the ``15 j + 6`` pose vector for ``num_joints`` joints."""

    num_joints: int

    @property
    def size(self) -> int:
        return 15 * self.num_joints + 6

    def _s(self, start, width):
        return slice(start, start + width)

    @property
    def local_positions(self) -> slice:
        return self._s(0, 3 * self.num_joints)

    @property
    def local_rotations(self) -> slice:
        return self._s(3 * self.num_joints, 6 * self.num_joints)

    @property
    def local_velocities(self) -> slice:
        return self._s(9 * self.num_joints, 3 * self.num_joints)

    @property
    def local_angular_velocities(self) -> slice:
        return self._s(12 * self.num_joints, 3 * self.num_joints)

    @property
    def root_velocity(self) -> slice:
        return self._s(15 * self.num_joints, 3)

    @property
    def root_angular_velocity(self) -> slice:
        return self._s(15 * self.num_joints + 3, 3)


@dataclasses.dataclass(frozen=True)
class RootSpec:
    """Which joints define the character root on a skeleton (names, so any rig works)."""

    spine: str
    hips: str
    left_hip: str | None
    right_hip: str | None

    @staticmethod
    def for_skeleton(skeleton: Skeleton) -> "RootSpec":
        names = skeleton.names
        root = next(i for i, p in enumerate(skeleton.parents) if p < 0)
        # The hips: the first joint with two or more children among the root's descendants (static
        # wrappers such as Bandai-Namco's joint_Root have a single child).
        hips = root
        while True:
            children = [i for i, p in enumerate(skeleton.parents) if p == hips]
            if len(children) != 1:
                break
            hips = children[0]
        # The "second spine joint": two steps up the spine chain from the hips.
        chain = [hips]
        for _ in range(2):
            kids = [i for i, p in enumerate(skeleton.parents) if p == chain[-1]]
            spine_kids = [i for i in kids if "spine" in names[i].lower() or "chest" in names[i].lower()]
            if not spine_kids:
                break
            chain.append(spine_kids[0])
        left = _find(names, ("LeftUpLeg", "UpperLeg_L", "LeftUpperLeg", "L_Hip", "LeftHip", "left_hip"))
        right = _find(names, ("RightUpLeg", "UpperLeg_R", "RightUpperLeg", "R_Hip", "RightHip", "right_hip"))
        return RootSpec(spine=names[chain[-1]], hips=names[hips], left_hip=left, right_hip=right)


def translated_joints(skeleton: Skeleton) -> tuple[int, ...]:
    """Joints whose translation a generated pose sets: the root and its single-child chain down to the hips.

    On the ZEGGS rig that is the root (Hips) alone; on Bandai-Namco it is the static wrapper ``joint_Root``
    and the animated ``Hips`` under it. Every other joint keeps its rest offset (bone length).
    """
    root = next(i for i, p in enumerate(skeleton.parents) if p < 0)
    hips = skeleton.index(RootSpec.for_skeleton(skeleton).hips)
    chain = [hips]
    while chain[-1] != root:
        chain.append(int(skeleton.parents[chain[-1]]))
    return tuple(sorted(chain))


def fk_fields(skeleton: Skeleton) -> dict:
    """The rig as ``ModelConfig`` fields (``fk_parents``, ``fk_offsets``, ``fk_translated``), so the losses
    can compute joint positions by forward kinematics of the predicted rotations (what is rendered)."""
    return {"fk_parents": tuple(int(p) for p in skeleton.parents),
            "fk_offsets": tuple(float(x) for x in np.asarray(skeleton.offsets, np.float64).ravel()),
            "fk_translated": translated_joints(skeleton)}


def fk_chain_matrix(parents, translated) -> tuple[np.ndarray, np.ndarray]:
    """``(anchor (J,), chain (J, J))`` for FK from root-frame rotations: joint j's position is
    ``pos[anchor[j]] + sum_k chain[j, k] * bone_k`` with ``bone_k = R_parent(k) offset_k``.

    ``anchor[j]`` is the nearest joint at or above j whose translation the pose sets (``translated``; the
    root always), ``chain[j, k] = 1`` for the joints k on the path from j up to, not including, the anchor.
    """
    parents = np.asarray(parents, np.int64)
    J = len(parents)
    fixed = set(int(t) for t in translated) | {j for j in range(J) if parents[j] < 0}
    anchor = np.zeros(J, np.int64)
    chain = np.zeros((J, J), np.float32)
    for j in range(J):
        k = j
        while k not in fixed:
            chain[j, k] = 1.0
            k = int(parents[k])
        anchor[j] = k
    return anchor, chain


def _find(names, candidates):
    for c in candidates:
        if c in names:
            return c
    return None


def _yaw_from_forward(forward: np.ndarray, up_axis: int) -> np.ndarray:
    """Quaternion about the up axis turning the world forward axis onto ``forward`` projected on ground."""
    f = np.array(forward, dtype=np.float64, copy=True)
    f[..., up_axis] = 0.0
    n = np.linalg.norm(f, axis=-1, keepdims=True)
    fwd_axis = _world_forward(up_axis)
    f = np.where(n > 1e-9, f / np.maximum(n, 1e-12), fwd_axis)
    return rotations.quat_between(np.broadcast_to(fwd_axis, f.shape), f)


def _world_forward(up_axis: int) -> np.ndarray:
    """World forward axis: +Z for Y-up, +Y for Z-up."""
    return np.array([0.0, 0.0, 1.0]) if up_axis == 1 else np.array([0.0, 1.0, 0.0])


def character_root(motion: Motion, spec: RootSpec | None = None):
    """Root transform per frame: ``(position (F, 3) on the ground, yaw quaternion (F, 4))``.

    References: Ghorbani et al. 2023, §3.2 ("projecting the position of the second spine joint on the
    ground ... the z-axis of the hip joint onto the ground to obtain the root orientation").
    """
    from jaxgest.motion.kinematics import forward_kinematics, global_rotations

    sk = motion.skeleton
    spec = spec or RootSpec.for_skeleton(sk)
    up = sk.up_axis
    pos = forward_kinematics(motion)
    root_pos = pos[:, sk.index(spec.spine)].copy()
    root_pos[:, up] = 0.0
    if spec.left_hip and spec.right_hip:
        lateral = pos[:, sk.index(spec.left_hip)] - pos[:, sk.index(spec.right_hip)]
        up_vec = np.zeros(3)
        up_vec[up] = 1.0
        # Right-handed axes: facing f with up u, the character's left is cross(u, f), so f = cross(left, u).
        forward = np.cross(lateral, up_vec)
    else:
        grot = global_rotations(motion)[:, sk.index(spec.hips)]
        forward = rotations.quat_rotate(grot, np.broadcast_to(_world_forward(up), grot.shape[:-1] + (3,)))
    return root_pos, _yaw_from_forward(forward, up)


def _backward_diff(x: np.ndarray, fps: float) -> np.ndarray:
    d = np.empty_like(x)
    d[1:] = (x[1:] - x[:-1]) * fps
    d[0] = d[1] if len(x) > 1 else 0.0
    return d


def _angular_velocity(q: np.ndarray, fps: float) -> np.ndarray:
    """Scaled angle-axis of ``q_t q_{t-1}^-1`` times fps, in the world frame; (F, ..., 3)."""
    w = np.empty(q.shape[:-1] + (3,))
    w[1:] = rotations.quat_to_expmap(rotations.quat_mul(q[1:], rotations.quat_inv(q[:-1]))) * fps
    w[0] = w[1] if len(q) > 1 else 0.0
    return w


def extract_features(motion: Motion, spec: RootSpec | None = None) -> dict:
    """Pose features of a motion (paper 001 §3.2).

    Returns a dict with ``features`` (F, 15j+6) float32, ``root_position`` (F, 3), ``root_rotation``
    (F, 4), ``world_positions`` (F, J, 3) and ``world_rotations`` (F, J, 4) (float64).
    """
    from jaxgest.motion.kinematics import forward_kinematics, global_rotations

    if motion.num_frames < 2:
        raise DataError(f"{motion.name or 'motion'}: needs at least 2 frames for velocities")
    fps = motion.fps
    pos = forward_kinematics(motion)
    grot = rotations.quat_unroll(global_rotations(motion), axis=0)
    root_pos, root_rot = character_root(motion, spec)
    root_rot = rotations.quat_unroll(root_rot, axis=0)
    inv_root = rotations.quat_inv(root_rot)[:, None]  # (F, 1, 4)
    J = motion.skeleton.num_joints

    local_pos = rotations.quat_rotate(inv_root, pos - root_pos[:, None])
    local_rot = rotations.quat_mul(np.broadcast_to(inv_root, grot.shape), grot)
    local_vel = rotations.quat_rotate(inv_root, _backward_diff(pos, fps))
    local_ang = rotations.quat_rotate(inv_root, _angular_velocity(grot, fps))
    root_vel = rotations.quat_rotate(inv_root[:, 0], _backward_diff(root_pos, fps))
    root_ang = rotations.quat_rotate(inv_root[:, 0], _angular_velocity(root_rot, fps))

    F = motion.num_frames
    feats = np.concatenate(
        [
            local_pos.reshape(F, 3 * J),
            rotations.quat_to_6d(local_rot).reshape(F, 6 * J),
            local_vel.reshape(F, 3 * J),
            local_ang.reshape(F, 3 * J),
            root_vel,
            root_ang,
        ],
        axis=-1,
    )
    return {
        "features": feats.astype(np.float32),
        "root_position": root_pos,
        "root_rotation": root_rot,
        "world_positions": pos,
        "world_rotations": grot,
    }


def pose_statistics(poses, *, input_norm: str = "group", trim: int = 2, eps: float = 1e-5):
    """Per-channel mean and std of pose features over training sequences, ``trim`` frames cut at both
    ends of each (their velocities are copies or boundary effects), std floored at ``eps`` only against
    division by zero. A :class:`jaxgest.motion.datasets.NormStats`; the outputs are denormalised with it and
    the inputs rescaled to one std per group (:func:`jaxgest.zeggs.generator.input_scale`).
    ``input_norm="channel"`` (the old behaviour, inputs normalised per channel): every frame, std floored
    at 1e-2.
    References: the authors' data_pipeline.py (statistics over ``s + 2 : e - 2`` of every clip; output
    std per channel, no floor).
    """
    from jaxgest.motion.datasets import NormStats

    if input_norm == "channel":
        return NormStats.from_data(list(poses))
    cut = [np.asarray(p)[trim:len(p) - trim] if len(p) > 2 * trim else np.asarray(p) for p in poses]
    return NormStats.from_data(cut, eps=eps)


def integrate_root(root_vel: np.ndarray, root_ang: np.ndarray, fps: float, start_pos=None, start_rot=None):
    """Integrate root velocities (in the root frame) into positions and yaw quaternions (NumPy).

    The same update the generator's character state applies in JAX (``update_character_state``).
    References: Ghorbani et al. 2023, §3.3 ("Update Character State").
    """
    F = len(root_vel)
    p = np.zeros(3) if start_pos is None else np.asarray(start_pos, np.float64)
    q = np.array([1.0, 0, 0, 0]) if start_rot is None else np.asarray(start_rot, np.float64)
    rot = np.zeros((F, 4))
    pos = np.zeros((F, 3))
    for t in range(F):
        if t > 0:
            turn = rotations.expmap_to_quat(rotations.quat_rotate(q, root_ang[t]) / fps)
            q = rotations.quat_normalize(rotations.quat_mul(turn, q))
            p = p + rotations.quat_rotate(q, root_vel[t]) / fps
        pos[t], rot[t] = p, q
    return pos, rot


def features_to_motion(features: np.ndarray, template: Motion, root_position: np.ndarray, root_rotation: np.ndarray,
                       fps: float | None = None, name: str | None = None) -> Motion:
    """Pose features + root transforms -> a Motion on ``template``'s skeleton.

    Local rotations come from the 6-D root-frame rotations; the root joint's translation from its
    root-frame position; other joints keep the template's rest translations (bone lengths).
    """
    sk = template.skeleton
    J = sk.num_joints
    layout = PoseLayout(J)
    F = features.shape[0]
    f = np.asarray(features, np.float64)
    rot6 = f[:, layout.local_rotations].reshape(F, J, 6)
    lpos = f[:, layout.local_positions].reshape(F, J, 3)
    root_rotation = np.asarray(root_rotation, np.float64)
    grot = rotations.quat_mul(np.broadcast_to(root_rotation[:, None], (F, J, 4)), rotations.sixd_to_quat(rot6))
    local = np.empty_like(grot)
    for j in range(J):
        p = sk.parents[j]
        local[:, j] = grot[:, j] if p < 0 else rotations.quat_mul(rotations.quat_inv(grot[:, p]), grot[:, j])
    # The root and the joints down to the hips (Bandai-Namco's Hips under a static joint_Root) get their
    # translation back from the predicted positions -- a property of the rig, not of the template's frames
    # (at inference the template repeats one frame); so do joints animated in a multi-frame template.
    # The others keep the template's rest offsets (bone lengths).
    world = rotations.quat_rotate(root_rotation[:, None], lpos) + np.asarray(root_position, np.float64)[:, None]
    trans = np.broadcast_to(sk.offsets[None], (F, J, 3)).copy()
    animated = template.translations.std(axis=0).max(axis=-1) > 1e-6
    animated[list(translated_joints(sk))] = True
    for j in range(J):
        p = sk.parents[j]
        if p < 0:
            trans[:, j] = world[:, j]
        elif animated[j]:
            trans[:, j] = rotations.quat_rotate(rotations.quat_inv(grot[:, p]), world[:, j] - world[:, p])
    return Motion(sk, rotations.quat_canonicalize(local), trans, fps or template.fps, name=name or template.name)


def local_to_world_positions(local_positions: jax.Array, root_position: jax.Array, root_rotation: jax.Array):
    """jnp: root-frame joint positions ``(..., J, 3)`` -> world ``(..., J, 3)`` (for world-space losses)."""
    return rotations.quat_rotate(root_rotation[..., None, :], local_positions) + root_position[..., None, :]


"""The ZeroEGGS authors' pose features of a clip: joint-local state, root frame and gaze (paper 001 §3.2-3.3).

:func:`pose_state` is the authors' ``data_pipeline.preprocess_animation`` on a jaxgest :class:`Motion` of
the ZEGGS rig (the joints named ``Hips``, ``Spine2`` and ``Head`` define the root and the gaze):

* root position: the world position of ``Spine2`` projected on the ground (Y-up);
* root rotation: the yaw taking +Z to the ground projection of the ``Hips`` z-axis;
* gaze: the ground projection of the ``Head`` z-axis, 100 cm ahead of the root; its per-clip median is the
  gaze target (one point per clip), ``gaze_dir`` that target in the root frame;
* ``lpos`` / ``lrot``: joint-local translations and rotations, the root joint's made relative to the root
  transform (``rho_p``, ``rho_r`` of the paper: "the joint local translations and rotations");
* ``ltxy``: the 2-axis form of ``lrot`` (the rotated x and y axes, ``(F, J, 2, 3)``);
* ``lvel`` / ``lvrt``: backward differences of ``lpos`` and of ``lrot`` (scaled angle-axis, ``/ dt``);
  ``root_vel`` / ``root_vrt``: the root's, in the previous frame's root frame; frame 0 is extrapolated as
  theirs (``v0 = v1 - (v3 - v2)``).

:func:`pose_vector` lays one frame out as the network reads it: ``[root_vel, root_vrt, lpos, ltxy, lvel,
lvrt]`` (``6 + 15 J`` channels), plus ``gaze_dir`` (3) for the decoder input (``anim_input``, ``9 + 15 J``).

References: Ghorbani et al. 2023, §3.2 (features), §3.3 (pose state); the authors' ``data_pipeline.py``
(``preprocess_animation``) and ``modules.py`` (``vectorize_input``).
"""

from __future__ import annotations

import numpy as np

from jaxgest.motion.skeleton import Motion
from jaxgest.runtime.errors import DataError
from jaxgest.zeggs.official import quat

GAZE_DISTANCE = 100.0  # cm: "assume other actor is one meter away" (theirs)
REQUIRED_JOINTS = ("Hips", "Spine2", "Head")
ZEGGS_JOINTS = {"hips": "Hips", "spine": "Spine2", "head": "Head"}


def root_joints(skeleton) -> dict[str, str]:
    """The joints that define the root and the gaze: the ZEGGS rig's ``Hips`` / ``Spine2`` / ``Head`` where it
    has them (the authors' choice); on another rig the hips and the second spine joint of
    :class:`jaxgest.zeggs.features.RootSpec` and the first joint named ``*head*`` (our generalisation)."""
    names = list(skeleton.names)
    if all(n in names for n in REQUIRED_JOINTS):
        return dict(ZEGGS_JOINTS)
    from jaxgest.zeggs.features import RootSpec

    spec = RootSpec.for_skeleton(skeleton)
    head = next((n for n in names if "head" in n.lower()), None)
    if head is None:
        raise DataError(f"the rig has no joint named like 'Head' (joints: {', '.join(names[:8])}, ...): the "
                        "authors' features need one for the gaze")
    return {"hips": spec.hips, "spine": spec.spine, "head": head}


def _extrapolate_first(x: np.ndarray) -> None:
    x[0] = x[1] - (x[3] - x[2])


def pose_state(motion: Motion, joints: dict | None = None) -> dict[str, np.ndarray]:
    """The authors' features of ``motion`` (float64): ``root_pos (F, 3)``, ``root_rot (F, 4)``, ``root_vel``,
    ``root_vrt (F, 3)``, ``lpos (F, J, 3)``, ``lrot (F, J, 4)``, ``ltxy (F, J, 2, 3)``, ``lvel``, ``lvrt
    (F, J, 3)``, ``gaze_pos (F, 3)`` (constant) and ``gaze_dir (F, 3)``. Needs 4 frames or more.
    ``joints``: ``{"hips", "spine", "head"}`` names (default: :func:`root_joints` of the clip's rig).
    References: the authors' ``data_pipeline.preprocess_animation``; Ghorbani et al. 2023, §3.2-3.3.
    """
    names = list(motion.skeleton.names)
    name = motion.name or "clip"
    try:
        joints = joints or root_joints(motion.skeleton)
    except DataError as e:
        raise DataError(f"{name}: {e}") from None
    missing = [n for n in joints.values() if n not in names]
    if missing:
        raise DataError(f"{name}: the authors' features need the joints {', '.join(joints.values())}; "
                        f"missing {', '.join(missing)}")
    if motion.num_frames < 4:
        raise DataError(f"{name}: {motion.num_frames} frames; the authors' velocities need at least 4")
    parents = [int(p) for p in motion.skeleton.parents]
    if parents[0] >= 0 or any(p >= i for i, p in enumerate(parents) if i > 0):
        raise DataError(f"{name}: joints must be ordered parents first, with the root first")
    dt = 1.0 / motion.fps
    lrot = quat.unroll(motion.rotations)
    lpos = np.array(motion.translations, np.float64, copy=True)
    grot, gpos = quat.fk(lrot, lpos, parents)

    root_pos = gpos[:, names.index(joints["spine"])] * np.array([1.0, 0.0, 1.0])
    root_fwd = quat.mul_vec(grot[:, names.index(joints["hips"])], np.array([[0.0, 0.0, 1.0]]))
    root_fwd[:, 1] = 0.0
    root_fwd = root_fwd / np.sqrt(np.sum(root_fwd * root_fwd, axis=-1))[..., None]
    root_rot = quat.normalize(quat.between(np.array([[0.0, 0.0, 1.0]]).repeat(len(root_fwd), 0), root_fwd))

    look = quat.mul_vec(grot[:, names.index(joints["head"])], np.array([0.0, 0.0, 1.0]))
    look[:, 1] = 0.0
    look = look / np.sqrt(np.sum(np.square(look), axis=-1))[..., None]
    gaze_pos = np.median(root_pos + GAZE_DISTANCE * look, axis=0)[None].repeat(len(root_pos), 0)
    gaze_dir = quat.mul_vec(quat.inv(root_rot), gaze_pos - root_pos)

    lrot[:, 0] = quat.mul(quat.inv(root_rot), lrot[:, 0])
    lpos[:, 0] = quat.mul_vec(quat.inv(root_rot), lpos[:, 0] - root_pos)

    lvel = np.zeros_like(lpos)
    lvel[1:] = (lpos[1:] - lpos[:-1]) / dt
    _extrapolate_first(lvel)
    lvrt = np.zeros_like(lpos)
    lvrt[1:] = quat.to_helical(quat.qabs(quat.mul(lrot[1:], quat.inv(lrot[:-1])))) / dt
    _extrapolate_first(lvrt)

    root_vrt = np.zeros_like(root_pos)
    root_vrt[1:] = quat.to_helical(quat.qabs(quat.mul(root_rot[1:], quat.inv(root_rot[:-1])))) / dt
    _extrapolate_first(root_vrt)
    root_vrt[1:] = quat.mul_vec(quat.inv(root_rot[:-1]), root_vrt[1:])
    root_vrt[0] = quat.mul_vec(quat.inv(root_rot[0]), root_vrt[0])
    root_vel = np.zeros_like(root_pos)
    root_vel[1:] = (root_pos[1:] - root_pos[:-1]) / dt
    _extrapolate_first(root_vel)
    root_vel[1:] = quat.mul_vec(quat.inv(root_rot[:-1]), root_vel[1:])
    root_vel[0] = quat.mul_vec(quat.inv(root_rot[0]), root_vel[0])

    return dict(root_pos=root_pos, root_rot=root_rot, root_vel=root_vel, root_vrt=root_vrt, lpos=lpos,
                lrot=lrot, ltxy=quat.two_axis(lrot), lvel=lvel, lvrt=lvrt, gaze_pos=gaze_pos, gaze_dir=gaze_dir)


def pose_vector(state: dict, *, gaze: bool) -> np.ndarray:
    """``(F, 6 + 15 J)`` ``[root_vel, root_vrt, lpos, ltxy, lvel, lvrt]``, with ``gaze_dir`` appended
    (``9 + 15 J``) when ``gaze`` (the decoder's and style encoder's input layout, ``anim_input``).
    References: the authors' ``modules.vectorize_input`` and ``generate.py`` (style example vector)."""
    F = len(state["lpos"])
    parts = [state["root_vel"], state["root_vrt"], state["lpos"], state["ltxy"], state["lvel"], state["lvrt"]]
    if gaze:
        parts.append(state["gaze_dir"])
    return np.concatenate([np.reshape(p, (F, -1)) for p in parts], axis=1)

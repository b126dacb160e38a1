"""Retargeting between rigs through their T-poses (world rotations relative to a shared reference posture).

Two rigs rarely share joint frames or rest poses: the Bandai-Namco body has every bone along its local X
(its identity pose is not a standing pose at all), ZEGGS has world-aligned frames and a T-pose rest. Each rig
therefore declares a *T-pose* (joint maps, ``maps/*.json``): the world rotation ``T_j`` of every joint when
the character stands Y-up, faces +Z, arms horizontal. A posture is the same on both rigs when every mapped
joint has turned by the same world rotation from its T-pose:

    D_j(t) = G^src_s(t) (T^src_s)^-1          (world "delta" of source joint s from its T-pose)
    G^tgt_j(t) = D_j(t) T^tgt_j                (target joint j = map(s) turned by the same delta)

which carries the full rotation (swing and twist) of every mapped joint, including leaf joints (hands, head,
toes) whose orientation bone directions alone cannot give. Where a rig skips joints (ZEGGS has Spine, Spine2
and Neck1 between mapped joints), a joint whose mapped chain continues through unmapped joints gets a
shortest-arc (swing-only) correction so the direction to its next mapped joint matches: on the source side
for how its unmapped joints bend, on the target side for how the template's unmapped joints bend. Branching
joints (hips, chest) are not corrected. Unmapped target joints keep the template's local rotations.
"""

from __future__ import annotations

import numpy as np

from jaxgest.motion import kinematics as K
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton

_AXES = {"X": 0, "Y": 1, "Z": 2}


def axes_to_quat(axes) -> np.ndarray:
    """World rotation (4,) whose local X, Y, Z axes point along ``axes``, e.g. ``("+Y", "-X", "+Z")``."""
    m = np.zeros((3, 3))
    for col, a in enumerate(axes):
        m[_AXES[a[1]], col] = -1.0 if a[0] == "-" else 1.0
    if abs(np.linalg.det(m) - 1.0) > 1e-9:
        raise ValueError(f"T-pose axes {axes} are not a right-handed frame")
    return R.matrix_to_quat(m)


def locals_from_globals(skeleton: Skeleton, g: np.ndarray) -> np.ndarray:
    """Local rotations ``(..., J, 4)`` from world rotations ``(..., J, 4)``: ``q_j = G_parent^-1 G_j``."""
    out = np.array(g, np.float64, copy=True)
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            out[..., j, :] = R.quat_mul(R.quat_inv(g[..., p, :]), g[..., j, :])
    return R.quat_canonicalize(out)


def rest_positions(skeleton: Skeleton, local_rotations: np.ndarray) -> np.ndarray:
    """World positions (J, 3) of ``skeleton`` in the pose ``local_rotations`` (J, 4) at its rest offsets."""
    m = Motion(skeleton, local_rotations[None], skeleton.offsets[None], 1.0)
    return K.forward_kinematics(m)[0]


def next_mapped(skeleton: Skeleton, j: int, mapped) -> list[list[int]]:
    """Paths from j (exclusive) to each nearest mapped descendant (inclusive), through unmapped joints."""
    out = []
    for c in np.flatnonzero(skeleton.parents == j):
        c = int(c)
        if c in mapped:
            out.append([c])
        else:
            out.extend([[c] + p for p in next_mapped(skeleton, c, mapped)])
    return out


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _chain_offset(path, rot, trans):
    """Offset (F, 3) of ``path[-1]`` in the frame of the joint before ``path[0]`` (via ``rot``, ``trans``)."""
    v = trans[:, path[-1]]
    for i in reversed(path[:-1]):
        v = trans[:, i] + R.quat_rotate(rot[:, i], v)
    return v


def retarget(source: Motion, source_tpose: np.ndarray, template: Motion, target_tpose: np.ndarray,
             pairs: dict, root_position: np.ndarray | None = None) -> Motion:
    """Pose ``template``'s rig like ``source`` (see the module docstring for the method).

    Args:
      source: motion on the source rig, F frames.
      source_tpose: (Js, 4) world rotations of the source joints in the source's T-pose.
      template: motion on the target rig with F frames or 1 (broadcast): skeleton, local translations and
        the local rotations of unmapped joints.
      target_tpose: (Jt, 4) world rotations of the target joints in the target's T-pose.
      pairs: target joint index -> source joint index.
      root_position: (F, 3) world position of the target's root-most mapped joint (default: the source's).

    Returns:
      A Motion on the template's skeleton with F frames at the source's frame rate.
    """
    tsk, ssk = template.skeleton, source.skeleton
    F = source.num_frames
    Gs, Ps = K.global_transforms(source)
    Ps0 = rest_positions(ssk, locals_from_globals(ssk, source_tpose))
    Pt0 = rest_positions(tsk, locals_from_globals(tsk, target_tpose))
    rot = np.broadcast_to(template.rotations, (F,) + template.rotations.shape[1:])
    trans = np.array(np.broadcast_to(template.translations, (F,) + template.translations.shape[1:]))
    mapped = set(pairs)
    G = np.empty((F, tsk.num_joints, 4))
    for j in range(tsk.num_joints):
        p = int(tsk.parents[j])
        if j not in mapped:
            G[:, j] = rot[:, j] if p < 0 else R.quat_mul(G[:, p], rot[:, j])
            continue
        s = pairs[j]
        delta = R.quat_mul(Gs[:, s], R.quat_inv(source_tpose[s]))
        paths = next_mapped(tsk, j, mapped)
        if len(paths) == 1 and np.linalg.norm(Pt0[paths[0][-1]] - Pt0[j]) > 1e-6:
            k = paths[0][-1]
            # Source side: how the source's unmapped in-between joints bend the chain.
            predicted = R.quat_rotate(delta, _unit(Ps0[pairs[k]] - Ps0[s]))
            actual = Ps[:, pairs[k]] - Ps[:, s]
            delta = R.quat_mul(R.quat_between(predicted, actual), delta)
            g = R.quat_mul(delta, target_tpose[j])
            if len(paths[0]) > 1:
                # Target side: the template's unmapped in-between joints.
                have = R.quat_rotate(g, _chain_offset(paths[0], rot, trans))
                want = R.quat_rotate(delta, Pt0[k] - Pt0[j])
                g = R.quat_mul(R.quat_between(have, want), g)
        else:
            g = R.quat_mul(delta, target_tpose[j])
        G[:, j] = g
    local = locals_from_globals(tsk, G)
    top = min(mapped, key=lambda j: _depth(tsk, j))
    want = Ps[:, pairs[top]] if root_position is None else np.asarray(root_position, np.float64)
    p = int(tsk.parents[top])
    if p < 0:
        trans[:, top] = want
    else:
        grot, gpos = K.global_transforms(Motion(tsk, local, trans, source.fps))
        trans[:, top] = R.quat_rotate(R.quat_inv(grot[:, p]), want - gpos[:, p])
    return Motion(tsk, local, trans, source.fps, name=source.name)


def _depth(sk: Skeleton, j: int) -> int:
    d = 0
    while sk.parents[j] >= 0:
        j = sk.parents[j]
        d += 1
    return d

"""Procedural posing of the 21-joint body: torso attitudes + two-bone IK -> local quaternions.

World axes (Bandai-Namco convention): X = the character's left, Y = up, Z = forward (the character faces
+Z, the camera). A *reference* stance (torso upright, arms straight out sideways, legs straight down, feet
forward-down) is built once from the skeleton's own offsets, so the code needs only the joint names, not
any particular rest orientation. Each animated frame then gives:

* torso segments (Hips, Spine, Chest, Neck, Head): a world attitude ``M_j`` applied to the reference
  frame, ``G_j = M_j R_j``;
* limbs: a world direction per bone from two-bone IK; the bone's orientation is the shortest-arc swing of
  its parent-carried reference orientation onto that direction, so the local rotations are continuous
  and carry no spurious twist.

Local rotations are ``G_parent^T G_j`` (as unit quaternions, unrolled in time). Translations are the
rest offsets except for the root (Hips), whose per-frame world position places the lowest foot joint on
the floor (y = 0).
"""

from __future__ import annotations

import dataclasses
import types

import numpy as np

from jaxgest.motion import rotations as rot

X = np.array([1.0, 0.0, 0.0])
Y = np.array([0.0, 1.0, 0.0])
Z = np.array([0.0, 0.0, 1.0])

TORSO = ("Hips", "Spine", "Chest", "Neck", "Head")
SIDES = {"L": 1.0, "R": -1.0}  # world X sign of each side


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _frame(p, s):
    """Orthonormal basis (..., 3, 3) with columns p, s orthogonalised, p x s."""
    p = _unit(p)
    s = _unit(s - np.sum(s * p, axis=-1, keepdims=True) * p)
    return np.stack([p, s, np.cross(p, s)], axis=-1)


def _swing(u, v):
    """Shortest-arc rotation matrices taking directions u onto v (..., 3, 3)."""
    return rot.quat_to_matrix(rot.quat_between(u, v))


def _axis_angle(axis, deg):
    """Rotation matrices about a fixed world axis by angles ``deg`` (...,) in degrees."""
    deg = np.asarray(deg, dtype=np.float64)
    return rot.expmap_to_matrix(np.radians(deg)[..., None] * np.asarray(axis, dtype=np.float64))


def attitude(yaw, pitch, roll):
    """World rotation Ry(yaw) Rx(pitch) Rz(roll) in degrees; pitch > 0 leans forward, roll > 0 to the left."""
    return _axis_angle(Y, yaw) @ _axis_angle(X, pitch) @ _axis_angle(-Z, roll)


@dataclasses.dataclass(frozen=True)
class Rig:
    """Reference stance and bone geometry of a Bandai-like 21-joint skeleton (see module docstring)."""

    skeleton: object
    ref: np.ndarray  # (J, 3, 3) reference world orientations
    axis: np.ndarray  # (J, 3) local bone direction (towards the main child)
    lengths: dict  # bone lengths (cm) used by the IK

    def __post_init__(self):  # shared through a memo (synthetic._rig): read-only, so no caller can change it
        for name in ("ref", "axis"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "lengths", types.MappingProxyType(dict(self.lengths)))

    def idx(self, name):
        return self.skeleton.index(name)


def _main_child(skel, j):
    kids = [c for c in range(skel.num_joints) if skel.parents[c] == j]
    preferred = {"Hips": "Spine", "Chest": "Neck"}.get(skel.names[j])
    if preferred is not None:
        return skel.index(preferred)
    return kids[0] if kids else None


def make_rig(skel) -> Rig:
    """Build the reference stance of ``skel`` (names as in docs/design.md §2: Hips ... Toes_R)."""
    J = skel.num_joints
    off = skel.offsets
    axis = np.zeros((J, 3))
    for j in range(J):
        c = _main_child(skel, j)
        axis[j] = _unit(off[c] if c is not None and np.linalg.norm(off[c]) > 1e-6 else off[j])
    ref = np.zeros((J, 3, 3))
    i = skel.index
    foot_dir = _unit(np.array([0.0, -np.sin(np.radians(35)), np.cos(np.radians(35))]))
    target = {"Spine": Y, "Neck": Y, "Head": Y}
    for s, sx in SIDES.items():
        for n in ("Shoulder", "UpperArm", "LowerArm", "Hand"):
            target[f"{n}_{s}"] = sx * X
        target[f"UpperLeg_{s}"] = -Y
        target[f"LowerLeg_{s}"] = -Y
        target[f"Foot_{s}"] = foot_dir
        target[f"Toes_{s}"] = Z
    for j in range(J):
        name = skel.names[j]
        if name == "Hips":
            lat = off[i("UpperLeg_L")] - off[i("UpperLeg_R")]
            ref[j] = _frame(Y, X) @ _frame(axis[j], lat).T
        elif name == "Chest":
            lat = off[i("Shoulder_L")] - off[i("Shoulder_R")]
            ref[j] = _frame(Y, X) @ _frame(axis[j], lat).T
        else:
            carried = ref[skel.parents[j]]
            ref[j] = _swing(carried @ axis[j], target[name]) @ carried
    lengths = {}
    for s in SIDES:
        lengths[f"upper_{s}"] = float(np.linalg.norm(off[i(f"LowerArm_{s}")]))
        lengths[f"lower_{s}"] = float(np.linalg.norm(off[i(f"Hand_{s}")]))
        lengths[f"thigh_{s}"] = float(np.linalg.norm(off[i(f"LowerLeg_{s}")]))
        lengths[f"shin_{s}"] = float(np.linalg.norm(off[i(f"Foot_{s}")]))
        lengths[f"foot_{s}"] = float(np.linalg.norm(off[i(f"Toes_{s}")]))
    return Rig(skel, ref, axis, lengths)


def two_bone_ik(start, target, l1, l2, pole):
    """Elbow/knee and end positions reaching ``target`` from ``start`` (F, 3); the joint bends towards
    ``pole`` (F, 3). Unreachable targets are clamped to 99.5 % of the chain length."""
    d = target - start
    dist = np.linalg.norm(d, axis=-1, keepdims=True)
    u = d / np.maximum(dist, 1e-9)
    dist = np.clip(dist, abs(l1 - l2) + 1e-3, 0.995 * (l1 + l2))
    v = pole - np.sum(pole * u, axis=-1, keepdims=True) * u
    v = _unit(v)
    cos_a = np.clip((l1 * l1 + dist * dist - l2 * l2) / (2 * l1 * dist), -1.0, 1.0)
    mid = start + l1 * (cos_a * u + np.sqrt(1 - cos_a * cos_a) * v)
    return mid, start + dist * u


@dataclasses.dataclass
class PoseTracks:
    """Per-frame pose controls, all (F,) or (F, 3); angles in degrees, lengths in cm.

    ``hand[s]`` is the hand target relative to the upper-arm joint in the side frame (out, up, forward)
    of side ``s`` in {"L", "R"}; ``hips_offset`` moves the pelvis (x, y, z) relative to its stance
    position; ``torso[n]`` is a (F, 3) (yaw, pitch, roll) attitude per torso segment; ``shrug[s]`` is the
    clavicle elevation; ``knee_dip`` lowers the pelvis.
    """

    hand: dict
    torso: dict
    shrug: dict
    hips_offset: np.ndarray
    wrist: dict


def pose_to_motion_arrays(rig: Rig, tracks: PoseTracks):
    """Local rotations (F, J, 4) and translations (F, J, 3) of the posed body, feet on the floor."""
    skel = rig.skeleton
    J = skel.num_joints
    F = tracks.hips_offset.shape[0]
    off = skel.offsets
    G = np.zeros((F, J, 3, 3))
    P = np.zeros((F, J, 3))
    i = skel.index
    hips = i("Hips")
    lat_hip = np.linalg.norm(off[i("UpperLeg_L")] - off[i("UpperLeg_R")]) / 2
    leg = rig.lengths["thigh_L"] + rig.lengths["shin_L"]
    foot_len = rig.lengths["foot_L"]
    foot_pitch = np.radians(35.0)
    ankle_h = foot_len * np.sin(foot_pitch)
    stance_x = lat_hip + 3.0
    hip_drop = float(-(rig.ref[hips] @ off[i("UpperLeg_L")])[1])
    stand_y = ankle_h + 0.99 * leg + hip_drop
    P[:, hips] = np.array([0.0, stand_y, 1.0]) + tracks.hips_offset

    def carried(j):
        p = skel.parents[j]
        return G[:, p] @ (rig.ref[p].T @ rig.ref[j])

    def place(j):
        p = skel.parents[j]
        P[:, j] = P[:, p] + np.einsum("fab,b->fa", G[:, p], off[j])

    def aim(j, d):
        c = carried(j)
        G[:, j] = _swing(c @ rig.axis[j], d) @ c

    for n in TORSO:
        j = i(n)
        yaw, pitch, roll = tracks.torso[n][:, 0], tracks.torso[n][:, 1], tracks.torso[n][:, 2]
        G[:, j] = attitude(yaw, pitch, roll) @ rig.ref[j]
        if n != "Hips":
            place(j)
    body_yaw = attitude(tracks.torso["Hips"][:, 0], np.zeros(F), np.zeros(F))
    for s, sx in SIDES.items():
        # clavicle: reference sideways direction raised by the shrug angle, in the chest's attitude
        sh = i(f"Shoulder_{s}")
        place(sh)
        chest_att = G[:, i("Chest")] @ rig.ref[i("Chest")].T
        G[:, sh] = chest_att @ _axis_angle(sx * Z, tracks.shrug[s]) @ rig.ref[sh]
        ua, la, hd = i(f"UpperArm_{s}"), i(f"LowerArm_{s}"), i(f"Hand_{s}")
        place(ua)
        local = tracks.hand[s] * np.array([sx, 1.0, 1.0])  # (out, up, fwd) -> world-aligned x, y, z
        target = P[:, ua] + np.einsum("fab,fb->fa", body_yaw, local)
        pole = np.einsum("fab,b->fa", body_yaw, np.array([0.45 * sx, -1.0, -0.35]))
        elbow, hand = two_bone_ik(P[:, ua], target, rig.lengths[f"upper_{s}"], rig.lengths[f"lower_{s}"], pole)
        aim(ua, elbow - P[:, ua])
        place(la)
        aim(la, hand - elbow)
        place(hd)
        fore = _unit(hand - elbow)
        aim(hd, _unit(fore + tracks.wrist[s][:, None] * Y))
    for s, sx in SIDES.items():
        ul, ll, ft, to = i(f"UpperLeg_{s}"), i(f"LowerLeg_{s}"), i(f"Foot_{s}"), i(f"Toes_{s}")
        place(ul)
        toe_out = np.radians(8.0) * sx
        fwd = np.array([np.sin(toe_out), 0.0, np.cos(toe_out)])
        foot_dir = np.cos(foot_pitch) * fwd - np.sin(foot_pitch) * Y
        ankle = np.array([sx * stance_x, ankle_h, 0.0]) - foot_len * np.cos(foot_pitch) * fwd * 0.0
        ankle = np.broadcast_to(ankle, (F, 3))
        pole = np.broadcast_to(np.array([0.15 * sx, 0.0, 1.0]), (F, 3))
        knee, ank = two_bone_ik(P[:, ul], ankle, rig.lengths[f"thigh_{s}"], rig.lengths[f"shin_{s}"], pole)
        aim(ul, knee - P[:, ul])
        place(ll)
        aim(ll, ank - knee)
        place(ft)
        aim(ft, np.broadcast_to(foot_dir, (F, 3)))
        place(to)
        aim(to, np.broadcast_to(fwd, (F, 3)))
    # floor contact: the lowest foot joint of each frame on y = 0
    feet = [i(n) for n in ("Foot_L", "Toes_L", "Foot_R", "Toes_R")]
    P[:, hips, 1] -= P[:, feet, 1].min(axis=1)
    local = np.zeros((F, J, 3, 3))
    for j in range(J):
        p = skel.parents[j]
        local[:, j] = G[:, j] if p < 0 else np.swapaxes(G[:, p], -1, -2) @ G[:, j]
    quats = rot.quat_unroll(rot.quat_canonicalize(rot.matrix_to_quat(local)), axis=0)
    trans = np.broadcast_to(off, (F, J, 3)).copy()
    trans[:, hips] = P[:, hips]
    return quats, trans

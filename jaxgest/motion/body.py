"""The papers' 21-joint body and the joint maps that bring any skeleton to it (SPEC §2).

Kuriyama et al. 2022 (§3.1) represent a pose by the exponential maps of 21 joints: 13 upper-body joints
(39 channels: the autoencoder's input) and 8 lower-body joints (24 channels: the lower decoder's output).
The root (hips) rotation has its yaw about the vertical axis removed before encoding; the yaw is copied back
from the content clip after transfer and the root height is set by floor contact.

Joint maps are data (``maps/*.json``): body joint name -> joint of a rig. ``bandai_namco`` is the identity
on the dataset's own rig (a lossless round trip); ``zeggs`` maps the 75-joint ZEGGS rig. Rigs whose joint
frames differ from the body's (ZEGGS) are retargeted by *direction matching*: each mapped joint's world
rotation is the rotation that points its bones to the next mapped joints along the same world directions
as in the source (a least-squares fit, Wahba's problem, where a joint has two or more mapped children; the
smallest rotation from the template pose where it has one). Unmapped joints (fingers, extra spine joints)
keep the template's local rotations; twist about a single bone follows the template.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import pathlib
from typing import Optional

import numpy as np

from jaxgest.errors import DataError
from jaxgest.motion import kinematics as K
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton

UPPER = ("Hips", "Spine", "Chest", "Neck", "Head", "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L",
         "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R")
LOWER = ("UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R")
BODY = UPPER + LOWER
HANDS = ("Hand_L", "Hand_R")
ARMS = ("Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L", "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R")
FEET = ("Foot_L", "Toes_L", "Foot_R", "Toes_R")
UPPER_CHANNELS = 3 * len(UPPER)  # 39
LOWER_CHANNELS = 3 * len(LOWER)  # 24

MAPS_DIR = pathlib.Path(__file__).with_name("maps")


@functools.lru_cache(maxsize=None)
def load_map(name: str) -> dict:
    """The joint map ``name`` (``maps/{name}.json``): ``{"joints": {body_joint: rig_joint}, ...}``."""
    path = MAPS_DIR / f"{name}.json"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in MAPS_DIR.glob("*.json")))
        raise DataError(f"no joint map named {name!r} (known: {known})")
    return json.loads(path.read_text())


def available_maps() -> list[str]:
    return sorted(p.stem for p in MAPS_DIR.glob("*.json"))


def detect_map(skeleton: Skeleton) -> str:
    """Name of the joint map whose rig joints all exist in ``skeleton`` (identity maps first)."""
    names = set(skeleton.names)
    for name in available_maps():
        if set(load_map(name)["joints"].values()) <= names:
            return name
    raise DataError(
        f"skeleton with joints {', '.join(skeleton.names[:6])}, ... matches no joint map "
        f"({', '.join(available_maps())}); add one in jaxgest/motion/maps/"
    )


@functools.lru_cache(maxsize=None)
def body_skeleton() -> Skeleton:
    """The canonical 21-joint body (Bandai-Namco rig without its static ``joint_Root``), root = Hips.

    Y-up, centimetres, bones along each joint's local X (left) / -X (right) like the dataset's rig.
    """
    s = load_map("bandai_namco")["body_skeleton"]
    names = tuple(s["names"])
    ends = {names.index(k): np.asarray(v, np.float64) for k, v in s["end_sites"].items()}
    return Skeleton(names=names, parents=np.asarray(s["parents"]), offsets=np.asarray(s["offsets"], np.float64),
                    end_sites=ends, up_axis=int(s["up_axis"]))


@functools.lru_cache(maxsize=None)
def reference_pose() -> np.ndarray:
    """A neutral standing pose of the body (21, 4) local quaternions: the twist reference of retargeting.

    Taken from the built-in synthetic generator's neutral style, so no dataset file is needed.
    """
    from jaxgest.motion.synthetic import render_clip

    motion, _, _ = render_clip("story", "neutral", seed=0)
    return motion.rotations[0].copy()


@dataclasses.dataclass(frozen=True)
class BodyClip:
    """A motion in the body representation of paper 000.

    Attributes:
      upper: (F, 39) exp-maps of UPPER (the hips without yaw).
      lower: (F, 24) exp-maps of LOWER.
      yaw: (F, 4) the removed root yaw (quaternion about the up axis).
      root_position: (F, 3) world position of the hips.
      fps: frames per second.
    """

    upper: np.ndarray
    lower: np.ndarray
    yaw: np.ndarray
    root_position: np.ndarray
    fps: float

    @property
    def num_frames(self) -> int:
        return int(self.upper.shape[0])


def _indices(skeleton: Skeleton, joint_map: dict, names) -> list[int]:
    return [skeleton.index(joint_map["joints"][n]) for n in names]


def _is_identity_rig(map_name: str) -> bool:
    return map_name == "bandai_namco"


def motion_to_body(motion: Motion, map_name: Optional[str] = None) -> BodyClip:
    """Convert a motion on any mapped rig to the body representation (lossless on Bandai-Namco).

    References: Kuriyama et al. 2022, §3.1 (exp-map pose vector of 21 joints, root yaw cancelled).
    """
    map_name = map_name or detect_map(motion.skeleton)
    if not _is_identity_rig(map_name):
        motion = retarget_to_body(motion, map_name)
        map_name = "bandai_namco"
    jm = load_map(map_name)
    sk = motion.skeleton
    hips = sk.index(jm["joints"]["Hips"])
    root_position = K.forward_kinematics(motion)[:, hips]
    unyawed, yaw = K.remove_root_yaw(motion, root=sk.names[hips])
    up = R.quat_to_expmap(unyawed.rotations[:, _indices(sk, jm, UPPER)])
    lo = R.quat_to_expmap(unyawed.rotations[:, _indices(sk, jm, LOWER)])
    F = motion.num_frames
    return BodyClip(up.reshape(F, UPPER_CHANNELS), lo.reshape(F, LOWER_CHANNELS), yaw, root_position, motion.fps)


def body_to_motion(upper: np.ndarray, lower: np.ndarray, template: Motion, *, yaw: Optional[np.ndarray] = None,
                   floor: bool = True, map_name: Optional[str] = None, name: Optional[str] = None) -> Motion:
    """Write body exp-maps back onto ``template``'s skeleton (and root path).

    The template supplies the skeleton, the root path (hips translation) and the rotations of joints the
    body does not have; ``yaw`` (default: the template's own) is restored on the hips; with ``floor`` the
    root height is then set so the lowest foot touches the floor (paper 000 §3.1). ``upper``/``lower`` must
    have the template's frame count.
    """
    F = template.num_frames
    upper = np.asarray(upper, np.float64).reshape(F, len(UPPER), 3)
    lower = np.asarray(lower, np.float64).reshape(F, len(LOWER), 3)
    map_name = map_name or detect_map(template.skeleton)
    if not _is_identity_rig(map_name):
        body_template = retarget_to_body(template, map_name)
        body = body_to_motion(upper, lower, body_template, yaw=yaw, floor=False, map_name="bandai_namco")
        out = retarget_from_body(body, template, map_name)
        out = K.floor_contact(out) if floor else out
        return out.replace(name=name or template.name)
    jm = load_map(map_name)
    sk = template.skeleton
    hips = sk.names[sk.index(jm["joints"]["Hips"])]
    unyawed, own_yaw = K.remove_root_yaw(template, root=hips)
    rot = unyawed.rotations.copy()
    rot[:, _indices(sk, jm, UPPER)] = R.expmap_to_quat(upper)
    rot[:, _indices(sk, jm, LOWER)] = R.expmap_to_quat(lower)
    out = K.restore_root_yaw(unyawed.replace(rotations=rot), own_yaw if yaw is None else yaw, root=hips)
    if floor:
        out = K.floor_contact(out, feet=[jm["joints"][n] for n in FEET])
    return out.replace(name=name or template.name)


# ---------------------------------------------------------------------------------------------------
# Retargeting by direction matching


def _next_mapped(skeleton: Skeleton, j: int, mapped: set) -> list[list[int]]:
    """Paths from j (exclusive) to each nearest mapped descendant (inclusive), through unmapped joints."""
    out = []
    for c in np.flatnonzero(skeleton.parents == j):
        c = int(c)
        if c in mapped:
            out.append([c])
        else:
            out.extend([[c] + p for p in _next_mapped(skeleton, c, mapped)])
    return out


def _wahba(local_vecs: np.ndarray, world_vecs: np.ndarray) -> np.ndarray:
    """Rotation (F, 4) best mapping unit ``local_vecs`` (F, K, 3) onto ``world_vecs`` (F, K, 3)."""
    b = np.einsum("fki,fkj->fij", world_vecs, local_vecs)
    u, _, vt = np.linalg.svd(b)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, 2] *= d[..., None]
    return R.matrix_to_quat(u @ vt)


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def retarget_positions(src_positions: np.ndarray, pairs: dict, template: Motion,
                       root_position: Optional[np.ndarray] = None) -> Motion:
    """Pose ``template``'s rig so its mapped bones point along the source's bone directions.

    Args:
      src_positions: (F, Js, 3) world positions of the source joints.
      pairs: target joint index -> source joint index.
      template: motion on the target rig with F frames (or 1, broadcast): unmapped joints keep its local
        rotations; it is also the twist reference of single-bone joints.
      root_position: (F, 3) world position for the target's mapped root-most joint (default: the source's).
    """
    sk = template.skeleton
    F = src_positions.shape[0]
    tmpl_rot = np.broadcast_to(template.rotations, (F,) + template.rotations.shape[1:])
    tmpl_trans = np.broadcast_to(template.translations, (F,) + template.translations.shape[1:])
    mapped = set(pairs)
    G = np.empty((F, sk.num_joints, 4))
    local = tmpl_rot.copy()
    for j in range(sk.num_joints):
        p = sk.parents[j]
        g_init = tmpl_rot[:, j] if p < 0 else R.quat_mul(G[:, p], tmpl_rot[:, j])
        G[:, j] = g_init
        if j not in mapped:
            continue
        local_vecs, world_vecs = [], []
        for path in _next_mapped(sk, j, mapped):
            # Offset of the mapped descendant in j's frame, through the template rotations of intermediates.
            v = tmpl_trans[:, path[-1]]
            for i in reversed(path[:-1]):
                v = tmpl_trans[:, i] + R.quat_rotate(tmpl_rot[:, i], v)
            w = src_positions[:, pairs[path[-1]]] - src_positions[:, pairs[j]]
            if np.linalg.norm(v, axis=-1).min() > 1e-6:
                local_vecs.append(_unit(v))
                world_vecs.append(_unit(w))
        if len(local_vecs) >= 2:
            lv, wv = np.stack(local_vecs, 1), np.stack(world_vecs, 1)
            rank_ok = np.linalg.matrix_rank(lv[0], tol=1e-3) >= 2
            if rank_ok:
                G[:, j] = _wahba(lv, wv)
            else:
                G[:, j] = R.quat_mul(R.quat_between(R.quat_rotate(g_init, lv[:, 0]), wv[:, 0]), g_init)
        elif len(local_vecs) == 1:
            G[:, j] = R.quat_mul(R.quat_between(R.quat_rotate(g_init, local_vecs[0]), world_vecs[0]), g_init)
        local[:, j] = G[:, j] if p < 0 else R.quat_mul(R.quat_inv(G[:, p]), G[:, j])
    trans = tmpl_trans.copy()
    top = min(mapped, key=lambda j: _depth(sk, j))
    want = src_positions[:, pairs[top]] if root_position is None else root_position
    p = sk.parents[top]
    if p < 0:
        trans[:, top] = want
    else:
        pre = Motion(sk, R.quat_canonicalize(local), trans, template.fps)
        grot, gpos = K.global_transforms(pre)
        trans[:, top] = R.quat_rotate(R.quat_inv(grot[:, p]), want - gpos[:, p])
    return Motion(sk, R.quat_canonicalize(local), trans, template.fps, name=template.name)


def _depth(sk: Skeleton, j: int) -> int:
    d = 0
    while sk.parents[j] >= 0:
        j = sk.parents[j]
        d += 1
    return d


def retarget_to_body(motion: Motion, map_name: Optional[str] = None) -> Motion:
    """Any mapped rig -> a Motion on :func:`body_skeleton` (direction matching, neutral twist reference)."""
    map_name = map_name or detect_map(motion.skeleton)
    jm = load_map(map_name)["joints"]
    body = body_skeleton()
    pairs = {body.index(b): motion.skeleton.index(s) for b, s in jm.items()}
    ref = reference_pose()[None]
    template = Motion(body, ref, body.offsets[None], motion.fps, name=motion.name)
    pos = K.forward_kinematics(motion)
    return retarget_positions(pos, pairs, template)


def retarget_from_body(body_motion: Motion, template: Motion, map_name: Optional[str] = None) -> Motion:
    """A Motion on :func:`body_skeleton` -> ``template``'s rig (unmapped joints from the template)."""
    map_name = map_name or detect_map(template.skeleton)
    jm = load_map(map_name)["joints"]
    body = body_motion.skeleton
    pairs = {template.skeleton.index(s): body.index(b) for b, s in jm.items()}
    pos = K.forward_kinematics(body_motion)
    out = retarget_positions(pos, pairs, template)
    return out.replace(fps=body_motion.fps)

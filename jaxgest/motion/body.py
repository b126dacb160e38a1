"""The papers' 21-joint body and the joint maps that bring any skeleton to it (docs/design.md §2).

Kuriyama et al. 2022 (§3.1) represent a pose by the exponential maps of 21 joints: 13 upper-body joints
(39 channels: the autoencoder's input) and 8 lower-body joints (24 channels: the lower decoder's output).
The root (hips) rotation has its yaw about the vertical axis removed before encoding; the yaw is copied back
from the content clip after transfer and the root height is set by floor contact.

Joint maps are data (``maps/*.json``): body joint name -> joint of a rig, plus the rig's T-pose.
``bandai_namco`` is the identity on the dataset's own rig (a lossless round trip; ``joint_Root`` is a
static wrapper outside the body) and stores the canonical body skeleton (offsets, cm) and its T-pose axes,
so no data file is needed at run time. ``zeggs`` maps the 75-joint ZEGGS rig, whose rest pose is its T-pose.
Other rigs are retargeted through the T-poses (:mod:`jaxgest.motion.retarget`): every mapped joint turns
by the same world rotation away from its T-pose on both rigs (full rotations, so hands, head and twists
carry over), with a swing correction where a rig has extra joints in a chain. Unmapped joints (ZEGGS
fingers, Spine, Spine2, Neck1, HeadEnd) keep the template's local rotations. ZEGGS -> body -> ZEGGS on the
original template is lossless (1e-9).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import pathlib
from typing import Optional

import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.motion import kinematics as K
from jaxgest.motion import root_motion as RM
from jaxgest.motion.datasets import fit_frames, resample_motion
from jaxgest.motion import retarget as RT
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton

UPPER = ("Hips", "Spine", "Chest", "Neck", "Head", "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L",
         "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R")
LOWER = ("UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R")
BODY = UPPER + LOWER
HANDS = ("Hand_L", "Hand_R")
ARMS = ("Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L",
        "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R")
FEET = ("Foot_L", "Toes_L", "Foot_R", "Toes_R")
UPPER_CHANNELS = 3 * len(UPPER)  # 39
LOWER_CHANNELS = 3 * len(LOWER)  # 24

MAPS_DIR = pathlib.Path(__file__).with_name("maps")


@functools.lru_cache(maxsize=None)
def _map_text(name: str) -> str:
    path = MAPS_DIR / f"{name}.json"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in MAPS_DIR.glob("*.json")))
        raise DataError(f"no joint map named {name!r} (known: {known})")
    return path.read_text()


def load_map(name: str) -> dict:
    """The joint map ``name`` (``maps/{name}.json``): ``{"joints": {body_joint: rig_joint}, ...}``.

    A new dict on every call (the file's text is read once): a caller may change its copy freely.
    """
    return json.loads(_map_text(name))


def rig_joints(skeleton: Skeleton, names=BODY) -> list[str]:
    """The names in ``skeleton``'s rig of the body joints ``names`` (through its joint map)."""
    joints = load_map(detect_map(skeleton))["joints"]
    return [joints[n] for n in names]


def joint_indices(skeleton: Skeleton, names=BODY) -> list[int]:
    """The indices in ``skeleton`` of the body joints ``names`` (e.g. :data:`HANDS`, :data:`ARMS`)."""
    return [skeleton.index(j) for j in rig_joints(skeleton, names)]


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
    Memoised and shared: its arrays are read-only.
    """
    s = load_map("bandai_namco")["body_skeleton"]
    names = tuple(s["names"])
    ends = {names.index(k): _read_only(np.asarray(v, np.float64)) for k, v in s["end_sites"].items()}
    return Skeleton(names=names, parents=_read_only(np.asarray(s["parents"])),
                    offsets=_read_only(np.asarray(s["offsets"], np.float64)),
                    end_sites=ends, up_axis=int(s["up_axis"]))


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@functools.lru_cache(maxsize=16)
def tpose_globals(map_name: str, skeleton: Optional[Skeleton] = None) -> np.ndarray:
    """World rotations (J, 4) of a rig's joints in its T-pose (Y-up, facing +Z, arms horizontal).

    ``bandai_namco``: the body skeleton's T-pose from the map's ``tpose_axes`` (``skeleton`` ignored).
    Maps with ``"tpose": "rest"``: the rig's rest pose (identity local rotations) of ``skeleton``.
    The array is memoised per (map, skeleton) and shared, so it is read-only (copy it to change it).
    """
    jm = load_map(map_name)
    if "tpose_axes" in jm:
        sk = body_skeleton()
        return _read_only(np.stack([RT.axes_to_quat(jm["tpose_axes"][n]) for n in sk.names]))
    if jm.get("tpose") == "rest":
        if skeleton is None:
            raise ValueError(f"joint map {map_name!r} needs the rig's skeleton for its rest T-pose")
        ident = np.zeros((skeleton.num_joints, 4))
        ident[:, 0] = 1.0
        return _read_only(K.global_rotations(Motion(skeleton, ident[None], skeleton.offsets[None], 1.0))[0])
    raise DataError(f"joint map {map_name!r} defines no T-pose (tpose_axes or \"tpose\": \"rest\")")


def body_tpose() -> np.ndarray:
    """Local rotations (21, 4) of the canonical body T-pose (the retargeting reference posture)."""
    return RT.locals_from_globals(body_skeleton(), tpose_globals("bandai_namco"))


def rest_expmaps(joints=BODY) -> np.ndarray:
    """Exp-maps ``(J, 3)`` of the canonical body's rest (T-pose) local rotations of ``joints`` (names)."""
    names = body_skeleton().names
    q = body_tpose()[[names.index(j) for j in joints]]
    return np.asarray(R.quat_to_expmap(q), np.float64)


def nearest_branch(v: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Exp-maps ``(..., J, 3)`` -> the same rotations, each on the branch of the logarithm nearest ``ref`` (J, 3).

    A rotation by ``theta`` about the unit axis ``n`` is ``theta n`` on the principal branch (``|v| <= pi``) and
    equally ``(theta - 2 pi) n``; of the two this keeps the one nearer to the joint's ``ref`` (Euclidean).
    Joints that rest at a rotation of ~pi (the Bandai-Namco rig's upper legs, :func:`rest_expmaps`) jump
    between antipodal principal exp-maps whenever they cross pi (in 91 of the 144 training clips of
    experiments/tgst_bandai); on the branch nearest the rest pose they vary continuously. Joints resting
    near the identity are unchanged (the other branch has ``|v| >= pi``). Not in paper 000, which states
    exp-maps only: an option of the autoencoder's training targets
    (``AutoencoderTrainConfig.expmap_branch``); every value is still the exp-map of the same rotation.
    """
    v = np.asarray(v, np.float64)
    theta = np.linalg.norm(v, axis=-1, keepdims=True)
    alt = v - 2.0 * np.pi * v / np.maximum(theta, 1e-12)
    ref = np.asarray(ref, np.float64)
    keep = (np.square(v - ref).sum(-1) <= np.square(alt - ref).sum(-1))[..., None]
    return np.where(keep, v, alt)


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
    unyawed, yaw = RM.remove_root_yaw(motion, root=sk.names[hips])
    up = R.quat_to_expmap(unyawed.rotations[:, _indices(sk, jm, UPPER)])
    lo = R.quat_to_expmap(unyawed.rotations[:, _indices(sk, jm, LOWER)])
    F = motion.num_frames
    return BodyClip(up.reshape(F, UPPER_CHANNELS), lo.reshape(F, LOWER_CHANNELS), yaw, root_position,
                    motion.fps)


def body_to_motion(upper: np.ndarray, lower: np.ndarray, template: Motion, *,
                   yaw: Optional[np.ndarray] = None, root_position: Optional[np.ndarray] = None,
                   floor: bool = True, map_name: Optional[str] = None, name: Optional[str] = None) -> Motion:
    """Write body exp-maps back onto ``template``'s skeleton (and root path).

    Args:
      upper: (F, 39) and lower: (F, 24) exp-maps (:class:`BodyClip` layout), F = the template's frames.
      template: supplies the skeleton, the root path and the rotations of joints the body does not have.
      yaw: (F, 4) hips yaw restored on the result (default: the template's own).
      root_position: (F, 3) world position of the hips (default: the template's hips position, turned
        about the vertical axis by ``yaw`` relative to the template's yaw).
      floor: then set the root height per frame so the lowest foot/toe joint is at height 0
        (paper 000 §3.1); only the vertical coordinate of the root changes.

    References: Kuriyama et al. 2022, §3.1 (yaw copied back from the content, root height by FK).
    """
    F = template.num_frames
    for what, arr, ch in (("upper", upper, UPPER_CHANNELS), ("lower", lower, LOWER_CHANNELS)):
        if np.shape(arr) not in ((F, ch), (F, ch // 3, 3)):
            raise ValueError(f"body_to_motion: {what} has shape {np.shape(arr)}, expected ({F}, {ch}) "
                             f"for a template of {F} frames")
    upper = np.asarray(upper, np.float64).reshape(F, len(UPPER), 3)
    lower = np.asarray(lower, np.float64).reshape(F, len(LOWER), 3)
    map_name = map_name or detect_map(template.skeleton)
    if not _is_identity_rig(map_name):
        body_template = retarget_to_body(template, map_name)
        body = body_to_motion(upper, lower, body_template, yaw=yaw, root_position=root_position, floor=False,
                              map_name="bandai_namco")
        out = retarget_from_body(body, template, map_name)
        out = RM.floor_contact(out) if floor else out
        return out.replace(name=name or template.name)
    jm = load_map(map_name)
    sk = template.skeleton
    hips = sk.names[sk.index(jm["joints"]["Hips"])]
    unyawed, own_yaw = RM.remove_root_yaw(template, root=hips)
    rot = unyawed.rotations.copy()
    rot[:, _indices(sk, jm, UPPER)] = R.expmap_to_quat(upper)
    rot[:, _indices(sk, jm, LOWER)] = R.expmap_to_quat(lower)
    out = RM.restore_root_yaw(unyawed.replace(rotations=rot), own_yaw if yaw is None else yaw, root=hips)
    if root_position is not None:
        out = RM.set_root_position(out, root_position, root=hips)
    if floor:
        out = RM.floor_contact(out, feet=[jm["joints"][n] for n in FEET])
    return out.replace(name=name or template.name)


# ---------------------------------------------------------------------------------------------------
# Retargeting through T-poses (jaxgest.motion.retarget)


def retarget_to_body(motion: Motion, map_name: Optional[str] = None) -> Motion:
    """Any mapped rig -> a Motion on :func:`body_skeleton` (same world rotations relative to the T-poses).

    All 21 body joints are mapped, so the result depends on the source only; the hips are placed at the
    source hips' world position (no rescaling for the rigs' different sizes).
    """
    map_name = map_name or detect_map(motion.skeleton)
    jm = load_map(map_name)["joints"]
    body = body_skeleton()
    pairs = {body.index(b): motion.skeleton.index(s) for b, s in jm.items()}
    template = Motion(body, body_tpose()[None], body.offsets[None], motion.fps, name=motion.name)
    return RT.retarget(motion, tpose_globals(map_name, motion.skeleton), template,
                       tpose_globals("bandai_namco"), pairs)


def retarget_from_body(body_motion: Motion, template: Motion, map_name: Optional[str] = None) -> Motion:
    """A Motion on :func:`body_skeleton` -> ``template``'s rig.

    Unmapped joints of the rig (ZEGGS: fingers, Spine, Spine2, Neck1, HeadEnd, end joints) keep the
    template's local rotations (frame by frame when it has as many frames, else its first frame).
    """
    map_name = map_name or detect_map(template.skeleton)
    jm = load_map(map_name)["joints"]
    body = body_motion.skeleton
    pairs = {template.skeleton.index(s): body.index(b) for b, s in jm.items()}
    if template.num_frames != body_motion.num_frames:
        template = template.replace(rotations=template.rotations[:1], translations=template.translations[:1])
    out = RT.retarget(body_motion, tpose_globals("bandai_namco"), template,
                      tpose_globals(map_name, template.skeleton), pairs)
    return out.replace(name=template.name)


def to_rig(motion: Motion, template: Motion, *, fps: float | None = None, frames: int | None = None) -> Motion:
    """Put ``motion`` on ``template``'s rig: the one rig transfer of the package (pipeline and ZeroEGGS).

    Same joint names: the motion itself. Another rig: through the 21-joint body
    (:func:`retarget_to_body` / ``retarget_from_body`` with ``template``'s first frame as
    the target rest pose), then the root height is set per frame so the lowest foot/toe touches the floor
    (:func:`jaxgest.motion.kinematics.floor_contact`): legs of another length neither float nor sink. Then
    resampled to ``fps`` (None: kept) and cut or padded to ``frames`` (None: kept). The name is kept.
    """
    if motion.skeleton.names != template.skeleton.names:
        first = template.replace(rotations=template.rotations[:1], translations=template.translations[:1])
        moved = retarget_from_body(retarget_to_body(motion), first)
        motion = RM.floor_contact(moved).replace(name=motion.name)
    if fps is not None:
        motion = resample_motion(motion, fps)
    if frames is not None and frames != motion.num_frames:
        motion = fit_frames(motion, frames)
    return motion

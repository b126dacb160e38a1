"""TGST metric protocols (paper 000 §4.2; docs/design.md §5): how a clip becomes the features of the content and style
errors, and the per-clip errors themselves.

* :class:`Protocol` / :data:`PROTOCOLS` / :func:`get_protocol` -- ``authors`` (default, the paper tables) or
  ``world`` (ground-truth checks; the protocol of earlier runs).
* :func:`clip_features` / :func:`clip_errors` / :func:`features_errors` -- content error (eqs. 13-14, both
  hands, exact DTW) and style error (eqs. 15-16, arm-joint velocities) of one transferred clip, plus the same
  two errors against the ground-truth clip where the dataset has one.

The ``authors`` protocol (the authors' evaluator.py and dataset/mocap.py; docs/design.md §5):

* positions by forward kinematics with the root (the hips) at the origin and its rotation reset
  (:func:`jaxgest.motion.kinematics.root_local_positions`, ``get_joint_positions(root_positions=None)``);
* 1 s cut at both ends of every clip (60 frames at their 60 fps; round(fps) frames here, 30 on Bandai-Namco),
  before velocities; the content error compares the cut content with the cut transfer (their
  ``content[cut:-cut]`` / ``transfer[cut:-cut]``);
* velocities as the F - 1 forward differences x fps;
* every clip a transfer is compared with for *style* (the style clip; the ground truth in the gt and Table 1
  columns) is that clip followed by its mirror image (:func:`jaxgest.motion.kinematics.mirror`), blended over
  0.5 s (their 30 frames at 60 fps, ``append(..., transit=True, period=30)``). What the model itself is given
  is :func:`style_input_clip`: by default the same clip + mirror (the input of the experiments' results), or
  the style clip as is (``style_input="as-is"``).
* joints: both hands for the content error (their effector indices 7, 11 = LHand, RHand of their 13-joint
  upper body), the 8 arm joints (shoulder, upper arm, forearm, hand x L, R; their indices 4-11) for the
  style error; the 21-joint body's Hand_L/R and body.ARMS here, through the rig's joint map.
* window theta = 128 frames at 60 fps scaled with the rate (64 at 30 fps), hop theta/2.

Kept from the metric functions (:mod:`jaxgest.metrics.transfer_errors`), where the authors' code differs:
exact DTW instead of FastDTW; every full window (their ``range(0, F - theta, h)`` drops the last full window
when F - theta is a multiple of h); w25 = mean of the ceil(25 %) largest components (theirs: floor(n/4), NaN
below 4 components). Both protocols scale the cut with the clip rate.

The ``world`` protocol: world positions (root path and rotation included), backward differences with the
first velocity repeated, no cut, no mirror -- the numbers of earlier runs. Every report, table row and
summary names its protocol.

Units: BVH positions of both datasets and of the synthetic data are centimetres; hands are compared in
metres and velocities in metres per second, at the result's frame rate (a clip at another rate is
resampled to it).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from jaxgest import metrics
from jaxgest.runtime.errors import DataError
from jaxgest.motion import body, kinematics
from jaxgest.motion.skeleton import Motion
from jaxgest.tgst.config import STYLE_INPUTS  # noqa: F401  (re-exported: the style inputs of a transfer)

CM_TO_M = 0.01


# --------------------------------------------------------------------------------------------------------
# Protocols


@dataclasses.dataclass(frozen=True)
class Protocol:
    """How a clip becomes metric features (module docstring). Hashable; ``name`` labels every number."""

    name: str
    root_local: bool  # positions with the root at the origin and its rotation reset
    trim_seconds: float  # cut at both ends (round(trim_seconds * fps) frames)
    forward_differences: bool  # F - 1 forward differences (else F backward, the first repeated)
    mirror_style: bool  # style references are the clip followed by its mirror
    transition_seconds: float = 0.5  # blend between a style reference and its mirror
    common_length: bool = False  # result and compared clip cut to the shorter one's frames (authors' evaluator)

    def trim_frames(self, fps: float) -> int:
        return int(math.floor(self.trim_seconds * float(fps) + 0.5))

    def transition_frames(self, fps: float) -> int:
        return int(math.floor(self.transition_seconds * float(fps) + 0.5))

    @property
    def label(self) -> str:
        """``name`` plus any setting that differs from the named protocol (e.g. ``authors(trim 0.5 s)``)."""
        base = PROTOCOLS.get(self.name)
        if base is None or base == self:
            return self.name
        diffs = [f"{f.name}={getattr(self, f.name)}" for f in dataclasses.fields(self)
                 if f.name != "name" and getattr(self, f.name) != getattr(base, f.name)]
        if [d.split("=")[0] for d in diffs] == ["trim_seconds"]:
            return f"{self.name}(trim {self.trim_seconds:g} s)"
        return f"{self.name}({', '.join(diffs)})"

    def describe(self) -> dict:
        return {"name": self.label, **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                                        if f.name != "name"}}


PROTOCOLS = {
    "authors": Protocol("authors", root_local=True, trim_seconds=1.0, forward_differences=True, mirror_style=True,
                        common_length=True),
    "world": Protocol("world", root_local=False, trim_seconds=0.0, forward_differences=False, mirror_style=False),
}


def get_protocol(protocol="authors", trim_seconds: float | None = None) -> Protocol:
    """A :class:`Protocol` from its name (or itself), with the cut optionally overridden (seconds >= 0)."""
    if isinstance(protocol, Protocol):
        p = protocol
    elif protocol in PROTOCOLS:
        p = PROTOCOLS[protocol]
    else:
        raise DataError(f"evaluate: unknown protocol {protocol!r} (choose from {', '.join(PROTOCOLS)})")
    if trim_seconds is not None:
        if not (trim_seconds >= 0 and math.isfinite(trim_seconds)):
            raise DataError(f"evaluate: --trim must be >= 0 seconds, got {trim_seconds}")
        p = dataclasses.replace(p, trim_seconds=float(trim_seconds))
    return p


def _notes(protocol: Protocol) -> dict:
    cut = f"{protocol.trim_seconds:g} s cut at both ends" if protocol.trim_seconds else "no cut"
    pos = "root-local positions (root at the origin, root rotation reset)" if protocol.root_local \
        else "world positions"
    vel = "F-1 forward differences" if protocol.forward_differences else "backward differences, v[0] = v[1]"
    mirror = "style references = clip + its mirror (0.5 s blend)" if protocol.mirror_style else "no mirror"
    if protocol.common_length:
        mirror += "; result and content (or ground truth) cut to a common length"
    return {
        "protocol": f"{protocol.label}: {pos}; {vel}; {cut}; {mirror}",
        "content": "eqs. 13-14: both hands' positions in metres, exact DTW (not FastDTW); mean/worst/w25",
        "style": "eqs. 15-16: arm-joint (8) velocities in m/s, sum over joints of ||dmean|| + ||dstd||, theta = 128 "
        "frames at 60 fps scaled with the rate, hop theta/2; mean/worst/w25",
        "w25": "mean of the ceil(25%) largest components (at least one)",
        "gt": "gt_content / gt_style: the same errors with the dataset clip of the content in the target style",
        "controls": "content_as_is / style_as_is: the content clip / the style clip itself taken as the result",
        "averages": "each statistic averaged over the evaluated pairs (paper Tables 2/3)",
    }


# --------------------------------------------------------------------------------------------------------
# Per-clip features and errors


def _joint_indices(motion: Motion, names: Sequence[str]) -> list[int]:
    return body.joint_indices(motion.skeleton, names)


def style_reference(motion: Motion, protocol="authors") -> Motion:
    """The clip a transfer's *style* is compared with: ``motion`` followed by its mirror (0.5 s blend) under
    a protocol with ``mirror_style``, else ``motion`` itself.

    The mirror is :func:`jaxgest.tgst.data.mirror_motion`: :func:`jaxgest.motion.kinematics.mirror` with the
    rig's T-pose, exactly as the training data are mirrored. Without it the mirrored local rotations of a
    rig whose identity pose is not symmetric (Bandai-Namco) sit on the other branch, and the 0.5 s blend
    from the clip into its mirror swings the arms through the body (up to 0.6 m off at 9-28 m/s).

    References: the authors' evaluator (``setup_mirror_motions``); Kuriyama et al. 2022, §4.1 ("style
    gesture is augmented by computing mirror symmetry" in the evaluation phase).
    """
    from jaxgest.tgst.data import mirror_motion  # the training data's mirror (rig T-pose)

    p = get_protocol(protocol)
    if not p.mirror_style:
        return motion
    return kinematics.append_motion(motion, mirror_motion(motion), p.transition_frames(motion.fps))




def check_style_input(style_input: str) -> None:
    """DataError unless ``style_input`` is one of :data:`STYLE_INPUTS`."""
    if style_input not in STYLE_INPUTS:
        raise DataError(f"unknown style input {style_input!r} (choose from {', '.join(STYLE_INPUTS)})")


def style_input_clip(motion: Motion, style_input: str = "mirror", protocol="authors") -> Motion:
    """The style clip the model is given for the exemplar ``motion``: followed by its mirror (0.5 s blend,
    :func:`style_reference`) for ``"mirror"``, ``motion`` itself for ``"as-is"`` (:data:`STYLE_INPUTS`).

    The one function behind every transfer's style input: :meth:`jaxgest.tgst.api.TGSTModel.transfer` (the
    CLI, the pipeline, the demo) and the multi-take evaluation (:mod:`jaxgest.tgst.multitake_eval`, the
    experiments). The mirrored clip keeps the exemplar's name, so errors name its file. Raises DataError for
    an unknown ``style_input`` or a rig the mirror cannot handle.
    References: Kuriyama et al. 2022, §4.1 ("style gesture is augmented by computing mirror symmetry").
    """
    check_style_input(style_input)
    if style_input == "as-is":
        return motion
    p = get_protocol(protocol)
    if not p.mirror_style:  # the mirror input is the authors' protocol's reference, whichever protocol scores
        p = PROTOCOLS["authors"]
    try:
        mirrored = style_reference(motion, p)
    except (KeyError, ValueError, DataError) as e:
        raise DataError(f"{motion.name or 'style'}: cannot mirror the style clip ({e}); "
                        "--style-input as-is gives it as is") from None
    return mirrored.replace(name=motion.name)


def clip_features(motion: Motion, fps: float | None = None, protocol="authors",
                  reference: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(hands (F', 6) m, arm velocities (F'', 24) m/s)`` of a motion on any mapped rig, under ``protocol``.

    Hands: positions of body.HANDS (left, right); arms: per-second velocities of body.ARMS (8 joints),
    mapped to the rig's joint names through its joint map, positions in cm -> m. ``fps`` (default the
    motion's) resamples the motion first so velocities and windows compare at one rate. ``reference``: the
    clip is a style reference (:func:`style_reference`: followed by its mirror under the authors' protocol).
    Under the authors' protocol F' = F - 2 cut and F'' = F' - 1; under ``world`` F' = F'' = F.
    Raises DataError (naming the clip) when it is too short for the cut.
    References: Kuriyama et al. 2022, §4.2 (6-D hand positions in metres; velocities of arm joints); the
    authors' evaluator.py; docs/design.md §5.
    """
    p = get_protocol(protocol)
    if fps is not None and abs(float(fps) - motion.fps) > 1e-9:
        from jaxgest.motion.datasets import resample_motion

        motion = resample_motion(motion, float(fps))
    if reference:
        motion = style_reference(motion, p)
    pos = kinematics.root_local_positions(motion) if p.root_local else kinematics.forward_kinematics(motion)
    cut = p.trim_frames(motion.fps)
    if cut:
        if len(pos) <= 2 * cut + 1:
            raise DataError(f"{motion.name or 'clip'}: {len(pos)} frames is too short to cut {cut} frames at "
                            f"both ends ({p.label} protocol)")
        pos = pos[cut:-cut]
    hands = metrics.hands_metres(pos, _joint_indices(motion, body.HANDS))
    arms = metrics.arm_velocities(pos, motion.fps, _joint_indices(motion, body.ARMS), scale=CM_TO_M,
                                  forward=p.forward_differences)
    return hands, arms


def common_length(a_feats, b_feats) -> tuple[tuple, tuple]:
    """Two :func:`clip_features` tuples (of clips at one rate, one protocol) cut to the shorter clip's frames:
    the features the clips would have had if both had been cut to ``min(F_a, F_b)`` frames first (prefixes:
    hands ``F - 2 cut`` frames, velocities one fewer under forward differences).

    As the authors' evaluator, which cuts content and transfer to their common length before the 1 s cut
    at both ends (``content[:clip]``, ``transfer[:clip]``) and scores the style of the cut transfer.
    A transfer has its content's length (unchanged); the controls and Table 1 compare clips of other lengths.
    References: the authors' evaluator.py (``evaluate_distance``).
    """
    n = min(len(a_feats[0]), len(b_feats[0]))

    def cut(f):
        lag = len(f[0]) - len(f[1])  # 1 under forward differences, 0 under backward ones
        return f[0][:n], f[1][:max(n - lag, 0)]

    return cut(a_feats), cut(b_feats)


def features_errors(result_feats, content_feats, style_feats, gt_feats=None, *, window: int,
                    gt_reference_feats=None, common: bool = True) -> dict:
    """The errors of :func:`clip_errors` from precomputed :func:`clip_features` tuples (hands, arm vel).

    ``style_feats`` are the style *reference* features (``reference=True``); ``gt_feats`` the ground truth's
    plain features (for gt_content) and ``gt_reference_feats`` its reference features (for gt_style;
    default ``gt_feats``). ``common`` (the protocol's ``common_length``): the result is cut to a common
    length with the content clip for the content and both style errors, and with the ground truth for
    gt_content (:func:`common_length`, as the authors' evaluator, where the ground truth plays the content
    clip's part; the style references are taken whole, as theirs).
    References: Kuriyama et al. 2022, eqs. 13-16; the authors' evaluator.py.
    """
    res, con = common_length(result_feats, content_feats) if common else (result_feats, content_feats)
    out = {
        "content": metrics.content_error(con[0], res[0]),
        "style": metrics.style_error(res[1], style_feats[1], window),
    }
    if gt_feats is not None:
        ref = gt_feats if gt_reference_feats is None else gt_reference_feats
        res_gt, gt = common_length(result_feats, gt_feats) if common else (result_feats, gt_feats)
        out["gt_content"] = metrics.content_error(gt[0], res_gt[0])
        out["gt_style"] = metrics.style_error(res[1], ref[1], window)
    return out


def clip_errors(result: Motion, content: Motion, style: Motion, ground_truth: Motion | None = None, *,
                protocol="authors") -> dict:
    """Errors of one transferred clip: ``{"content", "style"[, "gt_content", "gt_style"]}`` under ``protocol``.

    Each value is ``{"mean", "worst", "w25"}``. content: E^content between the content clip's and the
    result's hands (DTW-aligned, metres); style: E^style of the result's arm-joint velocities against the
    style reference's windows (the style clip + its mirror under the authors' protocol; theta =
    window_for_fps(result.fps)); gt_content / gt_style: the same two errors with the ground-truth clip
    (content performed in the target style) in place of the content and of the style clip, only when
    ``ground_truth`` is given. All clips are compared at the result's frame rate. Raises DataError when a
    clip is too short for the protocol's cut or one style window.

    References: Kuriyama et al. 2022, eqs. 13-16 and §4.3 (imitated ground truth); docs/design.md §5.
    """
    p = get_protocol(protocol)
    fps = result.fps
    gt = gt_ref = None
    if ground_truth is not None:
        gt = clip_features(ground_truth, fps, p)
        gt_ref = clip_features(ground_truth, fps, p, reference=True)
    return features_errors(clip_features(result, fps, p), clip_features(content, fps, p),
                           clip_features(style, fps, p, reference=True), gt,
                           window=metrics.window_for_fps(fps), gt_reference_feats=gt_ref, common=p.common_length)

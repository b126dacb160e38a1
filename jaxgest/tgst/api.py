"""Public TGST entry points (docs/design.md §7): parameter counts, loading a trained workdir, Motion-level transfer.

* :func:`count_params` -- parameter counts of a fresh model of a preset (shapes only).
* :func:`load` (also ``load_model``) -- a :class:`TGSTModel` from a workdir written by ``jaxgest tgst
  train`` (checkpoints found through :mod:`jaxgest.tgst.workdir`). The model owns its compiled functions
  (one jit per transfer method, compiled per clip shape on first use); keep it to reuse them.
* :func:`transfer` -- ``transfer(content, style, *, workdir, method)``: what ``jaxgest tgst transfer`` calls
  (loads the workdir on every call).

Transfer of two :class:`~jaxgest.motion.skeleton.Motion` clips on any mapped rig (Bandai-Namco, ZEGGS, the
synthetic body), following §3.1 of the paper:

1. both clips are resampled to the model rate (``cfg.fps``) and converted to the 21-joint body exp-maps with
   the root's yaw about the vertical axis removed (:func:`jaxgest.motion.body.motion_to_body`);
2. the jit-compiled :func:`jaxgest.tgst.model.transfer_arrays` (encode both, tokens, transformer, swap,
   cross-fade, both decoders) gives upper and lower exp-maps of the content's length;
3. the result is resampled back to the content's frame times (quaternion slerp), written onto the content's
   skeleton with the content's root yaw and horizontal root path (:func:`jaxgest.motion.body.body_to_motion`),
   and the root height is set per frame so the lowest foot/toe joint is where the content's lowest foot/toe
   joint is on that frame (:meth:`TGSTModel.to_motion`, :func:`content_floor_contact`; paper §3.1, docs/design.md §3): the
   result keeps the content's contact height (4.25 cm for the foot joints of a standing Bandai-Namco actor,
   not 0) and leaves the floor when the content does. ``tolerance > 0`` (not the paper's; off by default)
   keeps the lowest foot within that distance of the content's on its contact frames with the root's vertical
   shift of least total variation instead, so that errors of the decoded legs do not move the whole body.

The output has the content's skeleton, frame count and frame rate. Joints outside the 21-joint body (e.g.
ZEGGS fingers) keep the content's rotations.
References: Kuriyama et al. 2022, §3.1 and Fig. 2.
"""

from __future__ import annotations

import functools
from typing import Optional

import jax
import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.motion import body, bvh, datasets
from jaxgest.motion import root_motion as RM
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion
from jaxgest.tgst import workdir as W
from jaxgest.tgst.config import Config, ModelConfig
from jaxgest.tgst.config import preset as preset_config
from jaxgest.tgst.model import METHODS, init_params, transfer_arrays


def count_params(preset="paper") -> dict[str, int]:
    """Parameter counts ``{"autoencoder": int, "transformer": int}`` of a fresh model of ``preset`` (a preset
    name, a :class:`~jaxgest.tgst.config.Config` or a :class:`~jaxgest.tgst.config.ModelConfig`).

    Computed with ``jax.eval_shape`` (no weights are materialised). Paper: 23,743 and 50,240.
    """
    cfg = preset_config(preset) if isinstance(preset, str) else preset
    cfg = cfg.model if isinstance(cfg, Config) else cfg
    shapes = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.key(0))
    return {name: int(sum(x.size for x in jax.tree_util.tree_leaves(tree))) for name, tree in shapes.items()}


def compiled_transfer(cfg: ModelConfig, method: str):
    """A new jit-compiled :func:`transfer_arrays` of one (config, method); one compilation per clip shape,
    kept by the returned function (a :class:`TGSTModel` keeps one per method)."""
    return jax.jit(functools.partial(transfer_arrays, cfg=cfg, method=method))


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise DataError(f"unknown transfer method {method!r} (choose from {', '.join(METHODS)})")


def _check_motion(m: Motion, what: str) -> None:
    label = m.name or what
    if not (np.all(np.isfinite(m.rotations)) and np.all(np.isfinite(m.translations))):
        raise DataError(f"{label}: {what} motion contains NaN or inf values")


def resample_body(x: np.ndarray, src_fps: float, dst_fps: float, frames: int) -> np.ndarray:
    """Body exp-maps ``(F, 3J)`` at ``src_fps`` -> ``(frames, 3J)`` at the times ``k / dst_fps`` (slerp)."""
    F = x.shape[0]
    q = R.expmap_to_quat(np.asarray(x, np.float64).reshape(F, -1, 3))
    i0, i1, w = datasets.resample_weights(F, src_fps, dst_fps, frames)
    out = R.quat_slerp(q[i0], q[i1], np.broadcast_to(w[:, None], (frames, q.shape[1])))
    return np.asarray(R.quat_to_expmap(out)).reshape(frames, -1)


class TGSTModel:
    """A trained TGST model: config, both parameter pytrees and its compiled functions; ``transfer`` works on
    Motions or BVH paths.

    Attributes:
      cfg: the :class:`~jaxgest.tgst.config.ModelConfig` of the networks.
      params: ``{"autoencoder": ..., "transformer": ...}``.
      workdir: where it was loaded from (None when built from parameters).
      config: the whole :class:`~jaxgest.tgst.config.Config` the workdir was trained with (None when built
        from parameters).
      steps: the checkpoint step of each stage that was loaded (``{}`` when built from parameters).
    """

    def __init__(self, cfg: ModelConfig, params: dict, workdir=None, *, config: Optional[Config] = None,
                 steps: Optional[dict] = None):
        if isinstance(cfg, Config):  # a whole preset: its model
            config, cfg = cfg if config is None else config, cfg.model
        self.cfg, self.params, self.workdir = cfg, params, workdir
        self.config, self.steps = config, dict(steps or {})
        self._compiled = {}  # method -> its jit-compiled transfer_arrays, owned by this model

    def compiled(self, method: str):
        """This model's jit-compiled :func:`transfer_arrays` for ``method`` (made on first use)."""
        _check_method(method)
        if method not in self._compiled:
            self._compiled[method] = compiled_transfer(self.cfg, method)
        return self._compiled[method]

    def min_frames(self, fps: float) -> int:
        """Shortest clip (frames at ``fps``) the model accepts: one token (16 frames) at the model rate."""
        return int(np.ceil(self.cfg.min_frames * fps / self.cfg.fps))

    def body_arrays(self, motion: Motion, what: str) -> np.ndarray:
        """A clip -> upper-body exp-maps ``(F', 39)`` float32 at the model rate (clear errors)."""
        _check_motion(motion, what)
        label = motion.name or what
        m = datasets.resample_motion(motion, self.cfg.fps)
        if m.num_frames < self.cfg.min_frames:
            raise DataError(f"{label}: {what} clip too short: {motion.num_frames} frames at {motion.fps:g} fps "
                            f"({m.num_frames} at the model's {self.cfg.fps:g} fps); TGST needs at least "
                            f"{self.min_frames(motion.fps)} frames ({self.cfg.min_frames} at {self.cfg.fps:g} fps)")
        try:
            return body.motion_to_body(m).upper.astype(np.float32)
        except (KeyError, DataError) as e:  # DataError: no joint map matches (its message names no file)
            raise DataError(f"{label}: {what} skeleton does not fit any joint map ({e})") from None

    def transfer_body(self, content_upper: np.ndarray, style_upper: np.ndarray, method: str = "soft"):
        """Arrays at the model rate: ``(Fc, 39)``, ``(Fs, 39)`` -> (upper ``(Fc, 39)``, lower ``(Fc, 24)``)."""
        up, lo, _ = self.compiled(method)(self.params, np.asarray(content_upper)[None], np.asarray(style_upper)[None])
        return np.asarray(up[0]), np.asarray(lo[0])

    def to_motion(self, upper: np.ndarray, lower: np.ndarray, content: Motion,
                  tolerance: Optional[float] = None) -> Motion:
        """Body exp-maps at the model rate ``(F', 39)``, ``(F', 24)`` -> a Motion on ``content``'s skeleton.

        Resampled to the content's frame times, written with the content's root yaw and horizontal path,
        the root height set so the lowest foot/toe joint is at the content's lowest foot/toe height, within
        ``tolerance`` on the content's contact frames (:func:`content_floor_contact`; default
        :data:`CONTACT_TOLERANCE`, 0 = per frame).
        References: Kuriyama et al. 2022, §3.1 (root position by forward kinematics from the feet).
        """
        F = content.num_frames
        up = resample_body(upper, self.cfg.fps, content.fps, F)
        lo = resample_body(lower, self.cfg.fps, content.fps, F)
        tol = CONTACT_TOLERANCE if tolerance is None else tolerance
        written = body.body_to_motion(up, lo, content, floor=False)
        return content_floor_contact(written, content, tolerance=tol)

    def transfer(self, content, style, method: str = "soft", name: Optional[str] = None,
                 tolerance: Optional[float] = None, style_input: str = "mirror") -> Motion:
        """``content`` performed in the style of ``style``, on the content's skeleton (module docstring).

        ``content`` / ``style``: Motions or BVH paths; ``method``: one of :data:`METHODS` (``"soft"``, the
        paper's swap; ``"coherent"``, not in the paper, for an exemplar of the content's gesture or its mirror);
        ``tolerance``: the floor contact's (:meth:`to_motion`; default per frame); ``style_input``: what the
        model is given, ``"mirror"`` (default: the exemplar followed by its mirror, the input of the
        experiments' results) or ``"as-is"`` (:func:`jaxgest.tgst.protocol.style_input_clip`)."""
        from jaxgest.tgst.protocol import check_style_input, style_input_clip

        _check_method(method)
        check_style_input(style_input)
        content, style = bvh.as_motion(content, "content"), bvh.as_motion(style, "style")
        cu = self.body_arrays(content, "content")
        self.body_arrays(style, "style")  # the exemplar's own errors (too short, no joint map) first
        su = self.body_arrays(style_input_clip(style, style_input), "style")
        up, lo = self.transfer_body(cu, su, method)
        out = self.to_motion(up, lo, content, tolerance=tolerance)
        return out.replace(name=name or f"{content.name or 'content'} in the style of {style.name or 'style'}")


def foot_names(skeleton) -> list[str]:
    """The rig's foot and toe joints of the 21-joint body (``body.FEET`` through its joint map)."""
    return body.rig_joints(skeleton, body.FEET)


CONTACT_TOLERANCE = 0.0
"""Default ``tolerance`` of :func:`content_floor_contact`: 0 = the per-frame contact of the paper (§3.1) and
docs/design.md §3. A tolerance (file units: cm on Bandai-Namco and ZEGGS) is an option: 0.9 cm removes 90 % of the arm
speed the per-frame contact adds on the held-out Bandai-Namco round trips, keeping the lowest foot joint
within 1 cm of the content's on every contact frame (experiments/tgst_bandai/README.md, section 2c)."""
CONTACT_BAND = 1.0
"""A content frame is a contact frame when its lowest foot/toe joint is within this of the clip's lowest."""


def content_contact_frames(content: Motion, band: float = CONTACT_BAND) -> np.ndarray:
    """``(F,)`` bools: the frames where ``content``'s lowest foot/toe joint is within ``band`` (file units)
    of its lowest height over the clip (standing or stepping, not in the air)."""
    return _contact(RM.lowest_foot_height(content, foot_names(content.skeleton)), band)


def _contact(low: np.ndarray, band: float = CONTACT_BAND) -> np.ndarray:
    """Contact frames of a lowest-foot height series (:func:`content_contact_frames`)."""
    return low < low.min() + band


def content_floor_contact(result: Motion, content: Motion, tolerance: float = CONTACT_TOLERANCE) -> Motion:
    """``result`` with its root height set so its lowest foot/toe joint is at the height of ``content``'s
    lowest foot/toe joint, within ``tolerance`` on the content's contact frames (same skeleton and frame
    count).

    ``tolerance=0``: the per-frame contact of docs/design.md §3 (paper §3.1) on every frame (flight phases included:
    :func:`jaxgest.motion.kinematics.floor_contact`). ``tolerance > 0``: on the contact frames
    (:func:`content_contact_frames`) the lowest foot joint stays within ``tolerance`` of the content's, the
    other frames (the content in the air) are free, and the root's vertical shift is the one of least total
    variation (:func:`jaxgest.motion.kinematics.floor_contact_tube`): errors of the decoded legs no longer
    move the whole body up and down on every frame (experiments/tgst_bandai/README.md, section 2c). Keeps
    the content's contact height (its foot joints' height above the floor when standing); only the root's
    vertical coordinate changes.
    References: Kuriyama et al. 2022, §3.1 (root position by forward kinematics from the feet). Difference
    (``tolerance > 0``): the lowest foot is within ``tolerance`` of the content's on contact frames, not on
    it.
    """
    feet = foot_names(content.skeleton)
    height = RM.lowest_foot_height(content, feet)
    if tolerance == 0:
        return RM.floor_contact(result, feet=feet, height=height)
    return RM.floor_contact_tube(result, feet=feet, height=height, tolerance=tolerance,
                                contact=_contact(height))  # content_contact_frames without a second FK


def load(workdir) -> TGSTModel:
    """Load the newest readable autoencoder and transformer checkpoints of a ``jaxgest tgst train`` workdir.

    Every call restores the checkpoints (a long-lived caller keeps the returned model, which also keeps its
    compiled functions). Raises CheckpointError when the workdir has no config.json or no checkpoint of
    either stage, or when the checkpoints do not match its config.
    """
    config = W.read_config(workdir)
    params, steps = W.restore_params(workdir, config.model)
    return TGSTModel(config.model, params, workdir, config=config, steps=steps)


load_model = load  # the name the CLI and older callers use


def transfer(content, style, *, workdir, method: str = "soft", style_input: str = "mirror") -> Motion:
    """Style transfer of two Motions (or BVH paths) with the model of ``workdir`` (docs/design.md §7), loaded now;
    see :meth:`TGSTModel.transfer` (``style_input``: ``"mirror"``, the default, or ``"as-is"``)."""
    from jaxgest.tgst.protocol import check_style_input

    _check_method(method)
    check_style_input(style_input)
    return load(workdir).transfer(content, style, method=method, style_input=style_input)


__all__ = ["METHODS", "TGSTModel", "compiled_transfer", "content_floor_contact", "count_params",
           "foot_names", "load", "load_model", "resample_body", "transfer"]

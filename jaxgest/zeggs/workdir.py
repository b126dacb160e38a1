"""A ZeroEGGS workdir: file names, ``config.json``, checkpoint meta and loading a trained model.

Imported by both training (:mod:`jaxgest.zeggs.trainer`) and inference (:mod:`jaxgest.zeggs.inference`,
:mod:`jaxgest.zeggs.evaluate`), so inference never imports the training module.

The workdir holds ``config.json`` (``"model": "zeggs"``, the preset name, the three-part config
:meth:`jaxgest.zeggs.config.Config.to_dict`, steps, seed, data folder, the rig, devices),
``pose_stats.json`` / ``speech_stats.json``, ``reference.bvh`` (a few frames of the training rig: the
template generation writes onto), ``checkpoints/zeggs/<step>/`` and ``metrics.jsonl``.

A checkpoint carries and checks only :func:`checkpoint_config`: the model part of the config and the pose
statistics shape (plus the skeleton signature, checked by :class:`jaxgest.runtime.training.Checkpointer`), so any
training or inference setting may change between a run and its resumption. Workdirs of earlier versions
(a flat config dict in ``config.json`` and in their checkpoints) are read through
:meth:`Config.from_dict`.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
from typing import Any, Mapping, Optional

import jax
import numpy as np

from jaxgest.runtime import provenance
from jaxgest.runtime.errors import CheckpointError
from jaxgest.motion import bvh
from jaxgest.motion.datasets import NormStats
from jaxgest.motion.skeleton import Motion
from jaxgest.runtime.training import FORMAT_VERSION, Checkpointer, check_workdir_config, write_json_atomic
from jaxgest.zeggs.config import MODEL_ADDED_FIELDS, Config, ModelConfig
from jaxgest.zeggs.model import param_shapes

KIND = "zeggs"  # config.json "model" and the checkpoint kind
CKPT_SUBDIR = "checkpoints/zeggs"
POSE_STATS, SPEECH_STATS, REFERENCE, CONFIG = "pose_stats.json", "speech_stats.json", "reference.bvh", "config.json"


def checkpoint_config(model: ModelConfig) -> dict:
    """What a checkpoint carries and a resumed run must match: the model config and the pose statistics
    shape."""
    return {**model.to_dict(), "pose_stats_shape": [model.pose_dim]}


def stored_checkpoint_config(config: Mapping[str, Any]) -> dict:
    """:func:`checkpoint_config` of a checkpoint's stored config: as is, or (a flat config of an earlier
    version, with its ``preset`` key) mapped through :meth:`Config.from_dict`; a model field added since
(:data:`MODEL_ADDED_FIELDS`) and missing takes the value the checkpoint was trained with."""
    if "pose_stats_shape" in config:  # a model section: fields added since take the value it was trained with
        return {**{k: v for k, v in MODEL_ADDED_FIELDS.items() if k not in config}, **config}
    flat = {k: v for k, v in config.items() if k != "preset"}
    try:
        return json.loads(json.dumps(checkpoint_config(Config.from_dict(flat).model)))  # lists, as stored
    except (TypeError, ValueError):
        return dict(config)  # left to Checkpointer.check_meta to report


class ZeggsCheckpointer(Checkpointer):
    """The :class:`jaxgest.runtime.training.Checkpointer` of a ZeroEGGS workdir: a stored meta item is compared as
    :func:`stored_checkpoint_config` (so checkpoints of earlier versions, with one flat config, are checked
    field by field against the model config instead of refused as another layout)."""

    def check_meta(self, stored: Optional[Mapping]) -> None:
        if stored is not None:
            stored = {**stored, "config": stored_checkpoint_config(stored.get("config") or {})}
        super().check_meta(stored)


def open_checkpoints(workdir, cfg: Config, skeleton: Optional[str], *, read_only: bool = False) -> Checkpointer:
    """The workdir's checkpointer for this model config and rig (:class:`ZeggsCheckpointer`)."""
    return ZeggsCheckpointer(workdir, kind=KIND, config=checkpoint_config(cfg.model), skeleton=skeleton,
                             subdir=CKPT_SUBDIR, read_only=read_only, ignore=())


def check_resumable(ckpt: Checkpointer) -> None:
    """Raise :class:`CheckpointError` when the newest checkpoint's meta does not match ``ckpt``'s model."""
    ckpt.check_meta(ckpt.stored_meta())


def write_config(workdir, cfg: Config, *, preset: str, steps: int, seed: int, data, skeleton, info: Mapping) -> None:
    """Write ``config.json`` (atomically)."""
    write_json_atomic(pathlib.Path(workdir) / CONFIG, {
        "model": KIND, "format_version": FORMAT_VERSION, "preset": preset, "config": cfg.to_dict(),
        "steps": steps, "seed": seed, "data": str(data), "skeleton": skeleton.signature(),
        "num_joints": skeleton.num_joints, **info, "code": provenance.code_stamp()})


def read_config(workdir) -> tuple[Config, dict]:
    """``(Config, config.json dict)`` of a trained workdir; one-line :class:`CheckpointError` otherwise."""
    workdir = pathlib.Path(workdir)
    path = workdir / CONFIG
    if not path.is_file():
        raise CheckpointError(f"{workdir}: no ZeroEGGS model here (missing config.json; train with "
                              "`jaxgest zeggs train --data DIR --workdir W`)")
    meta = check_workdir_config(workdir)  # one line for an unreadable, newer or unknown config.json
    if meta.get("model") != KIND:
        raise CheckpointError(f"{workdir}: holds a {meta.get('model', meta.get('kind', 'unknown'))!r} model, "
                              "not a ZeroEGGS model")
    try:
        cfg = Config.from_dict(meta["config"])
        meta["skeleton"]
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise CheckpointError(f"{path}: config from another version of jaxgest ({type(e).__name__}: {e}); "
                              "retrain into a new --workdir") from None
    return cfg, meta


@dataclasses.dataclass(frozen=True)
class TrainedWorkdir:
    """What inference needs from a workdir (:func:`load_workdir`)."""

    cfg: Config
    params: Any  # numpy parameter tree {"speech_encoder", "style_encoder", "generator"}
    pose_stats: NormStats
    speech_stats: NormStats
    reference: Motion  # a few frames of the training rig
    meta: dict  # config.json
    step: int  # the checkpoint step the parameters come from


def latest_step(workdir) -> Optional[int]:
    """The newest checkpoint step folder's number (None: none), from the folder names only."""
    folder = pathlib.Path(workdir) / CKPT_SUBDIR
    steps = [int(p.name) for p in folder.iterdir() if p.name.isdigit()] if folder.is_dir() else []
    return max(steps) if steps else None


def load_workdir(workdir) -> TrainedWorkdir:
    """The trained model of ``workdir``: config, parameters of the newest readable checkpoint, statistics and
    the reference rig (one-line :class:`CheckpointError` / :class:`DataError` for what is missing)."""
    workdir = pathlib.Path(workdir)
    cfg, meta = read_config(workdir)
    ckpt = open_checkpoints(workdir, cfg, meta["skeleton"], read_only=True)
    try:
        template = jax.tree_util.tree_map(lambda s: np.zeros(s.shape, s.dtype), param_shapes(cfg.model))
        params = ckpt.restore_params(template)
        step = ckpt.restored_step
    finally:
        ckpt.close()
    return TrainedWorkdir(cfg=cfg, params=params, pose_stats=NormStats.load(workdir / POSE_STATS),
                          speech_stats=NormStats.load(workdir / SPEECH_STATS),
                          reference=bvh.load(workdir / REFERENCE), meta=meta,
                          step=int(step) if step is not None else -1)

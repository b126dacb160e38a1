"""Train ZeroEGGS on a folder of BVH + WAV clips (ZEGGS layout or manifest.csv with audio).

``train(data_dir, workdir, preset="tiny", steps=None, seed=0, devices=None)``: builds the aligned
speech/pose sequences (mirrored, ±10 % speed), fits and saves the normalisation statistics, then runs the
jit-compiled RAdam step (data-parallel over ``devices``) with orbax checkpoints and ``metrics.jsonl``.
A killed run resumes from the last checkpoint with the same data order (batches are a pure function of
``(seed, step)``) and ends with the parameters of an uninterrupted run.

The workdir holds: ``config.json`` (preset, model config, device count, data folder, the rig),
``pose_stats.json`` / ``speech_stats.json``, ``reference.bvh`` (a few frames of the training rig: the
template generation writes onto), ``checkpoints/zeggs/`` and ``metrics.jsonl``.

References: Ghorbani et al. 2023, §4.3.
"""

from __future__ import annotations

import pathlib
import time
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest import parallel
from jaxgest.errors import CheckpointError, DataError, JaxgestError
from jaxgest.motion import bvh
from jaxgest.motion.datasets import NormStats, load_folder
from jaxgest.motion.synthetic.dataset import training_folder
from jaxgest.training import (FORMAT_VERSION, Checkpointer, MetricsLogger, TrainState, check_intervals,
                              check_steps, check_workdir_config, train_loop, write_json_atomic)
from jaxgest.zeggs import data as zdata
from jaxgest.zeggs import features as Fe
from jaxgest.zeggs.config import config_from_dict, get_config
from jaxgest.zeggs.steps import init_params, make_optimizer, make_train_step

KIND = "zeggs"
CKPT_SUBDIR = "checkpoints/zeggs"
IGNORED = ("steps", "xla_opt_level")  # config keys a resumed run may change (no effect on the parameters)
_COMPILED: dict = {}  # (config, statistics, devices, argument shapes) -> compiled train step, per process


def _config_for(preset: str, skeleton, overrides: Optional[dict] = None):
    try:
        return get_config(preset, num_joints=skeleton.num_joints, **{**Fe.fk_fields(skeleton), **(overrides or {})})
    except ValueError as e:
        raise DataError(str(e)) from None


def train(data_dir, workdir, *, preset: str = "tiny", steps: Optional[int] = None, seed: int = 0,
          devices: Optional[int] = None, progress: bool = True, log_every: int = 25,
          ckpt_every: Optional[int] = None, overrides: Optional[dict] = None) -> dict:
    """Train (or resume) ZeroEGGS on ``data_dir`` (None: the built-in synthetic data, written to
    ``workdir/synthetic-data``); returns a summary dict (final metrics, wall time, steps/s)."""
    parallel.maybe_initialize_distributed()
    check_steps(steps=steps)  # before any data is written
    check_intervals(log_every=log_every, ckpt_every=ckpt_every)
    data_dir = training_folder(data_dir, workdir, progress)  # None: the built-in synthetic data
    t0 = time.perf_counter()
    workdir = pathlib.Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    clips = [c for c in load_folder(data_dir, progress=progress) if c.audio is not None]
    if not clips:
        raise DataError(f"{data_dir}: no clip has audio (ZeroEGGS needs BVH + WAV pairs)")
    skeleton = clips[0].motion.skeleton
    cfg = _config_for(preset, skeleton, overrides)
    steps = int(steps if steps is not None else {"tiny": 300, "small": 8000}.get(preset, 120_000))

    stats_paths = workdir / "pose_stats.json", workdir / "speech_stats.json"
    resume = all(p.is_file() for p in stats_paths)
    pose_stats = NormStats.load(stats_paths[0]) if resume else None
    speech_stats = NormStats.load(stats_paths[1]) if resume else None
    a = cfg.speed_augmentation
    data = zdata.build(clips, fps=cfg.fps, mirror=cfg.mirror, speeds=(1 - a, 1.0, 1 + a) if a > 0 else (1.0,),
                       pose_stats=pose_stats, speech_stats=speech_stats, progress=progress, loudness=cfg.loudness,
                       input_norm=cfg.input_norm)
    if data.pose_dim != cfg.pose_dim:
        raise DataError(f"{data_dir}: pose features have {data.pose_dim} channels, the model expects {cfg.pose_dim}")

    mesh = parallel.make_mesh(devices)
    info = parallel.device_info(mesh)
    if cfg.batch_size % mesh.size:  # before any file of the workdir is written
        ok = [n for n in range(1, cfg.batch_size + 1) if cfg.batch_size % n == 0]
        raise JaxgestError(f"zeggs batch size {cfg.batch_size} does not divide over {mesh.size} devices; use "
                           f"--devices with one of {', '.join(map(str, ok))}")
    meta_config = {"preset": preset, **cfg.to_dict()}
    ckpt = Checkpointer(workdir, kind=KIND, config=meta_config, skeleton=skeleton.signature(), subdir=CKPT_SUBDIR,
                        ignore=IGNORED)
    if ckpt.latest_step() is not None:  # refuse a mismatching workdir before touching any of its files
        ckpt.check_meta(ckpt.stored_meta())
    if jax.process_index() == 0:
        if not resume:
            data.pose_stats.save(stats_paths[0])
            data.speech_stats.save(stats_paths[1])
        ref = clips[0].motion
        bvh.save(ref.replace(rotations=ref.rotations[:2], translations=ref.translations[:2]),
                 workdir / "reference.bvh")
        write_json_atomic(workdir / "config.json", {
            "model": KIND, "format_version": FORMAT_VERSION, "preset": preset, "config": cfg.to_dict(),
            "steps": steps, "seed": seed,
            "data": str(data_dir), "skeleton": skeleton.signature(), "num_joints": skeleton.num_joints,
            **info})

    tx = make_optimizer(cfg)
    params = init_params(cfg, jax.random.PRNGKey(seed))
    state = TrainState.create(apply_fn=None, params=params, tx=tx).replace(step=jnp.asarray(0, jnp.int32))
    state = parallel.replicate(state, mesh)
    state = ckpt.restore(state)
    start = int(jax.device_get(state.step))
    step_fn = _compiled_step(cfg, tx, data.pose_stats, mesh)

    def batch_fn(i):
        return data.batch(i, seed=seed, batch=cfg.batch_size, window=cfg.window,
                          style_min=cfg.style_window_min, style_max=cfg.style_window_max,
                          sampling=cfg.style_sampling)

    batches = parallel.sharded_batch_fn(batch_fn, mesh)
    logger = MetricsLogger(workdir, extra={"stage": KIND, **info})
    last = {}
    state = train_loop(state, step_fn, batches, key=jax.random.PRNGKey(seed + 1), num_steps=steps,
                       checkpointer=ckpt, logger=logger, log_every=log_every,
                       ckpt_every=ckpt_every if ckpt_every is not None else max(50, steps // 10), desc="zeggs",
                       progress=progress,
                       on_log=lambda s, m: last.update(m))
    ckpt.close()
    wall = time.perf_counter() - t0
    return {"steps": steps, "start_step": start, "wall_s": wall, "final": last, "devices": info["devices"],
            "sequences": len(data.sequences), "pose_dim": data.pose_dim}


def _compiled_step(cfg, tx, pose_stats, mesh):
    """The data-parallel jitted train step, compiled on first call with ``cfg.compiler_options``.

    Compiled executables are kept per (config, pose statistics, devices, argument shapes) in this process,
    so a resumed or repeated ``train`` in the same process does not compile again.
    """
    jitted = parallel.parallelize_step(
        make_train_step(cfg, tx, pose_mean=pose_stats.mean, pose_std=pose_stats.std), mesh)
    base = (cfg, np.asarray(pose_stats.mean, np.float32).tobytes(), np.asarray(pose_stats.std, np.float32).tobytes(),
            tuple(d.id for d in mesh.devices.flat))

    def step(state, batch, key):
        leaves, tree = jax.tree_util.tree_flatten((state, batch, key))
        k = base + (tree, tuple((tuple(x.shape), str(x.dtype)) for x in leaves))
        if k not in _COMPILED:
            if len(_COMPILED) >= 4:
                _COMPILED.pop(next(iter(_COMPILED)))
            _COMPILED[k] = jitted.lower(state, batch, key).compile(cfg.compiler_options)
        return _COMPILED[k](state, batch, key)

    return step


def load_workdir(workdir):
    """``(cfg, params, pose_stats, speech_stats, reference Motion, config.json dict)`` of a trained workdir."""
    workdir = pathlib.Path(workdir)
    cfg_path = workdir / "config.json"
    if not cfg_path.is_file():
        raise CheckpointError(f"{workdir}: no ZeroEGGS model here (missing config.json; train with "
                              "`jaxgest zeggs train --data DIR --workdir W`)")
    meta = check_workdir_config(workdir)  # one line for an unreadable, newer or unknown config.json
    if meta.get("model") != KIND:
        raise CheckpointError(f"{workdir}: holds a {meta.get('model', meta.get('kind', 'unknown'))!r} model, not a ZeroEGGS model")
    try:
        cfg, preset, skeleton = config_from_dict(meta["config"]), meta["preset"], meta["skeleton"]
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise CheckpointError(f"{cfg_path}: config from another version of jaxgest ({type(e).__name__}: {e}); "
                              "retrain into a new --workdir") from None
    ckpt = Checkpointer(workdir, kind=KIND, config={"preset": preset, **meta["config"]},  # as stored
                        skeleton=skeleton, subdir=CKPT_SUBDIR, read_only=True, ignore=IGNORED)
    template = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.PRNGKey(0))
    params = ckpt.restore_params(jax.tree_util.tree_map(lambda s: np.zeros(s.shape, s.dtype), template))
    ckpt.close()
    pose_stats = NormStats.load(workdir / "pose_stats.json")
    speech_stats = NormStats.load(workdir / "speech_stats.json")
    reference = bvh.load(workdir / "reference.bvh")
    return cfg, params, pose_stats, speech_stats, reference, meta

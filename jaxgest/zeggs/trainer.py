"""Train ZeroEGGS on a folder of BVH + WAV clips (ZEGGS layout or manifest.csv with audio).

``train(data_dir, workdir, preset="tiny", steps=None, seed=0, devices=None)``: builds the aligned
speech/pose sequences (mirrored, ±10 % speed), fits and saves the normalisation statistics, then runs the
jit-compiled RAdam step (data-parallel over ``devices``) with orbax checkpoints and ``metrics.jsonl``.
A killed run resumes from the last checkpoint with the same data order (batches are a pure function of
``(seed, step)``) and ends with the parameters of an uninterrupted run; SIGINT/SIGTERM save a checkpoint of the
interrupted step first (:func:`jaxgest.runtime.training.train_loop`). A training holds the workdir's writer lock
(:mod:`jaxgest.runtime.workdir_lock`: a second writer is refused). The data folder is given by the
caller (the CLI chooses the built-in synthetic data when none is named).

The workdir's files are described in :mod:`jaxgest.zeggs.workdir`; a resumed run must request the same
model config (any training setting may change).

References: Ghorbani et al. 2023, §4.3.
"""

from __future__ import annotations

import functools
import pathlib
import time
from typing import Optional

import jax
import jax.numpy as jnp

from jaxgest.runtime import parallel
from jaxgest.runtime.config import apply_overrides
from jaxgest.runtime.errors import DataError, JaxgestError
from jaxgest.motion import bvh
from jaxgest.motion.datasets import NormStats, load_folder
from jaxgest.runtime.training import (EVAL_BATCHES, EVAL_SEED, MetricsLogger, TrainState, bare_state,
                                      check_eval, check_intervals, check_steps, heldout_eval, jit_config_step,
                                      train_loop)
from jaxgest.zeggs import data as zdata
from jaxgest.zeggs import features
from jaxgest.zeggs import workdir as wd
from jaxgest.zeggs.config import Config, preset as get_preset
from jaxgest.zeggs.model import init_params
from jaxgest.zeggs.steps import loss_terms, make_optimizer, make_train_step, pose_stats as stats_arrays
from jaxgest.runtime.workdir_lock import exclusive_workdir


#: fields set from the training data's rig, never by an override
DATA_FIELDS = ("model.num_joints", "model.fk_parents", "model.fk_offsets", "model.fk_translated")


def config_for(preset: str, skeleton, overrides: Optional[dict] = None) -> Config:
    """The preset on ``skeleton``'s rig (joint count, FK fields), with dotted ``overrides``
    (``{"model.gru_hidden": 128}``, :func:`jaxgest.runtime.config.apply_overrides`)."""
    cfg = apply_overrides(get_preset(preset), overrides, model="ZeroEGGS", forbidden=DATA_FIELDS)
    try:
        return cfg.override(num_joints=skeleton.num_joints, **features.fk_fields(skeleton))
    except ValueError as e:
        raise DataError(str(e)) from None


def _train_step(state, batch, key, stats, cfg: Config):
    """One step of :func:`jaxgest.zeggs.steps.make_train_step` on a bare state (:func:`jaxgest.runtime.training.
    bare_state`), the optimiser rebuilt from the static config: module-level, so jit's own cache serves every
    training of one config in a process (:func:`jaxgest.runtime.training.jit_config_step`)."""
    state, metrics = make_train_step(cfg)(state.replace(tx=make_optimizer(cfg)), batch, key, stats)
    return bare_state(state), metrics


@functools.partial(jax.jit, static_argnames="cfg")
def _heldout_metrics(params, batch, step, key, stats, cfg: Config) -> dict:
    """The training step's metrics on a held-out batch, without dropout (``--eval-every``)."""
    terms = loss_terms(params, batch, key, step, cfg=cfg, pose_mean=stats["mean"], pose_std=stats["std"],
                       deterministic=True)
    return {k: jnp.mean(v) for k, v in terms.items()}


def _heldout_data(eval_data, skeleton, data, model, progress):
    """The held-out clips of ``eval_data`` as training data, normalised with the training statistics."""
    clips = [c for c in load_folder(eval_data, progress=progress) if c.audio is not None]
    if not clips:
        raise DataError(f"{eval_data}: no held-out clip has audio (ZeroEGGS needs BVH + WAV pairs)")
    for c in clips:
        if c.motion.skeleton.signature() != skeleton.signature():
            raise DataError(f"{c.path}: held-out clip on another skeleton than the training data")
    return zdata.build(clips, fps=model.fps, mirror=False, speeds=(1.0,), pose_stats=data.pose_stats,
                       speech_stats=data.speech_stats, progress=progress, loudness=model.loudness,
                       input_norm=model.input_norm)


def train(data_dir, workdir, *, preset: str = "tiny", steps: Optional[int] = None, seed: int = 0,
          devices: Optional[int] = None, progress: bool = True, log_every: int = 25,
          ckpt_every: Optional[int] = None, overrides: Optional[dict] = None, eval_data=None,
          eval_every: Optional[int] = None, tb_dir=None, profile_dir=None) -> dict:
    """Train (or resume) ZeroEGGS on ``data_dir``; returns a summary dict (final metrics, wall time, steps/s).

    ``steps``: total steps (default: the preset's ``train.steps``); ``overrides``: dotted config fields
    (``{"model.gru_hidden": 128, "train.learning_rate": 3e-4}``). ``eval_data`` / ``eval_every``: the loss
    on held-out clips (normalised with the training statistics; :data:`~jaxgest.runtime.training.EVAL_BATCHES`
    fixed batches, dropout off, the style sample from a fixed key) every ``eval_every`` steps, logged as
    ``eval_loss``, ``eval_recon``, ... (:func:`jaxgest.runtime.training.train_loop`); ``tb_dir``: TensorBoard
    events too; ``profile_dir``: a :func:`jax.profiler.trace` of a few steps.
    """
    parallel.maybe_initialize_distributed()
    check_steps(steps=steps)
    check_intervals(log_every=log_every, ckpt_every=ckpt_every, eval_every=eval_every)
    check_eval(eval_data, eval_every, log_every)
    if data_dir is None:
        raise JaxgestError("zeggs train: no data folder given")
    t0 = time.perf_counter()
    workdir = pathlib.Path(workdir)
    with exclusive_workdir(workdir, primary=jax.process_index() == 0):  # one writer per workdir
        workdir.mkdir(parents=True, exist_ok=True)
        clips = [c for c in load_folder(data_dir, progress=progress) if c.audio is not None]
        if not clips:
            raise DataError(f"{data_dir}: no clip has audio (ZeroEGGS needs BVH + WAV pairs)")
        skeleton = clips[0].motion.skeleton
        cfg = config_for(preset, skeleton, overrides)
        model, tcfg = cfg.model, cfg.train
        clips = zdata.exclude_styles(clips, tcfg.exclude_styles, data_dir)  # leave-one-style-out (zero-shot)
        steps = int(steps if steps is not None else tcfg.steps)

        stats_paths = workdir / wd.POSE_STATS, workdir / wd.SPEECH_STATS
        resume = all(p.is_file() for p in stats_paths)
        pose_stats = NormStats.load(stats_paths[0]) if resume else None
        speech_stats = NormStats.load(stats_paths[1]) if resume else None
        a = tcfg.speed_augmentation
        data = zdata.build(clips, fps=model.fps, mirror=tcfg.mirror, speeds=(1 - a, 1.0, 1 + a) if a > 0 else (1.0,),
                           pose_stats=pose_stats, speech_stats=speech_stats, progress=progress, loudness=model.loudness,
                           input_norm=model.input_norm, speech_method=model.speech_features)
        if data.pose_dim != model.pose_dim:
            raise DataError(f"{data_dir}: pose features have {data.pose_dim} channels, the model expects {model.pose_dim}")
        heldout = None
        if eval_data is not None:
            heldout = _heldout_data(eval_data, skeleton, data, model, progress)

        mesh = parallel.make_mesh(devices)
        info = parallel.device_info(mesh)
        if tcfg.batch_size % mesh.size:  # before any file of the workdir is written
            ok = [n for n in range(1, tcfg.batch_size + 1) if tcfg.batch_size % n == 0]
            raise JaxgestError(f"zeggs batch size {tcfg.batch_size} does not divide over {mesh.size} devices; use "
                               f"--devices with one of {', '.join(map(str, ok))}")
        ckpt = wd.open_checkpoints(workdir, cfg, skeleton.signature())
        wd.check_resumable(ckpt)  # refuse a mismatching workdir before touching any of its files
        if jax.process_index() == 0:
            if not resume:
                data.pose_stats.save(stats_paths[0])
                data.speech_stats.save(stats_paths[1])
            ref = clips[0].motion
            bvh.save(ref.replace(rotations=ref.rotations[:2], translations=ref.translations[:2]),
                     workdir / wd.REFERENCE)
            wd.write_config(workdir, cfg, preset=preset, steps=steps, seed=seed, data=data_dir, skeleton=skeleton,
                            info=info)

        params = init_params(model, jax.random.key(seed))
        state = TrainState.create(apply_fn=None, params=params, tx=make_optimizer(cfg))
        state = parallel.replicate(bare_state(state.replace(step=jnp.asarray(0, jnp.int32))), mesh)
        state = ckpt.restore(state)
        start = int(jax.device_get(state.step))
        stats = parallel.replicate(stats_arrays(model, data.pose_stats.mean, data.pose_stats.std), mesh)
        jitted = jit_config_step(_train_step, mesh, cfg, extra_args=1, compiler_options=tcfg.compiler_options)

        def step_fn(state, batch, key):
            return jitted(state, batch, key, stats)

        def batch_fn(i):
            return data.batch(i, seed=seed, batch=tcfg.batch_size, window=tcfg.window,
                              style_min=tcfg.style_window_min, style_max=tcfg.style_window_max,
                              sampling=tcfg.style_sampling)

        batches = parallel.sharded_batch_fn(batch_fn, mesh)
        eval_fn = None
        if heldout is not None:
            def heldout_batch(k):
                return heldout.batch(k, seed=EVAL_SEED, batch=tcfg.batch_size, window=tcfg.window,
                                     style_min=tcfg.style_window_min, style_max=tcfg.style_window_max,
                                     sampling=tcfg.style_sampling)

            fixed = [parallel.sharded_batch_fn(heldout_batch, mesh)(k) for k in range(EVAL_BATCHES)]
            eval_fn = heldout_eval(_heldout_metrics, fixed, jax.random.key(EVAL_SEED), stats, cfg)
        logger = MetricsLogger(workdir, extra={"stage": wd.KIND, **info},
                               tb_dir=tb_dir if jax.process_index() == 0 else None)
        last = {}
        try:
            state = train_loop(state, step_fn, batches, key=jax.random.key(seed + 1), num_steps=steps,
                               checkpointer=ckpt, logger=logger, log_every=log_every,
                               ckpt_every=ckpt_every if ckpt_every is not None else max(50, steps // 10),
                               desc="zeggs", progress=progress, on_log=lambda s, m: last.update(m),
                               eval_fn=eval_fn, eval_every=eval_every if eval_fn is not None else None,
                               profile_dir=profile_dir)
        finally:
            logger.close()
        ckpt.close()
        wall = time.perf_counter() - t0
        return {"steps": steps, "start_step": start, "wall_s": wall, "final": last, "devices": info["devices"],
                "sequences": len(data.sequences), "pose_dim": data.pose_dim}

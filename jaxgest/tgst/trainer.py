"""Train TGST: stage 1 the motion autoencoder, stage 2 the style transformer with the autoencoder frozen.

``train(data_dir, workdir, preset=...)`` is what ``jaxgest tgst train`` calls (the command line chooses the
data folder: ``--data`` or the built-in synthetic data). The workdir layout and the checkpoint checks are
in :mod:`jaxgest.tgst.workdir`; config.json stores the effective :class:`~jaxgest.tgst.config.Config`
(windows fitted to the data).

Both stages use optax Adam (§3.5), one jit-compiled step each (:func:`jaxgest.runtime.training.jit_config_step`,
state donated, batch split over the devices) and :func:`jaxgest.runtime.training.train_loop` (NaN stop, tqdm,
checkpoints, a checkpoint of the interrupted step on SIGINT/SIGTERM). A training holds the workdir's writer lock
(:mod:`jaxgest.runtime.workdir_lock`: a second writer is refused). A run resumes from the latest checkpoint of each stage; a finished autoencoder is not
retrained. The transformer's checkpoint records the autoencoder step it was trained on: when the autoencoder
has trained further, that transformer is moved aside (:func:`jaxgest.tgst.workdir.set_aside_stale_transformer`)
and retrained.

Step counts live in the preset (``train.autoencoder.steps``, ``train.transformer.steps``; the arguments
``ae_steps`` / ``transformer_steps`` replace them). References: Kuriyama et al. 2022, §3.5, §4.1.
"""

from __future__ import annotations

import functools
import pathlib
import time
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxgest.runtime import parallel, provenance, training
from jaxgest.runtime.workdir_lock import exclusive_workdir
from jaxgest.runtime.training import bare_state, jit_config_step
from jaxgest.runtime.config import apply_overrides as override_config
from jaxgest.runtime.errors import DataError, JaxgestError
from jaxgest.tgst import autoencoder
from jaxgest.tgst import data as tdata
from jaxgest.tgst.config import Config, preset as get_preset
from jaxgest.tgst.model import init_params
from jaxgest.tgst.steps import (ae_objective, create_ae_state, create_transformer_state, make_ae_train_step,
                                make_transformer_train_step, transformer_objective)
from jaxgest.tgst.workdir import (AE_KIND, AE_SUBDIR, MODEL, TRANSFORMER_KIND,  # noqa: F401  (re-exported)
                                  TRANSFORMER_SUBDIR, ae_checkpointer, check_existing,
                                  set_aside_stale_transformer, stored_transformer_meta,
                                  transformer_checkpointer)

def resolve_preset(preset: str) -> Config:
    """The preset ``preset`` (:data:`jaxgest.tgst.config.PRESETS`); an unknown name is one line."""
    return get_preset(preset)


LOSS_TERMS = ("identity", "cyclic", "structure", "appearance")


def apply_ablation(cfg: Config, ablate=()) -> Config:
    """``cfg`` with the named transformer loss terms switched off (paper Table 4); clear error otherwise."""
    ablate = tuple(ablate or ())
    unknown = [a for a in ablate if a not in LOSS_TERMS]
    if unknown:
        raise JaxgestError(f"unknown loss term {unknown[0]!r} to ablate (choose from {', '.join(LOSS_TERMS)})")
    if set(ablate) == set(LOSS_TERMS):
        raise JaxgestError("cannot ablate every loss term: the transformer would have nothing to learn")
    if not ablate:
        return cfg
    return apply_overrides(cfg, {f"train.transformer.use_{a}": False for a in ablate})


def apply_overrides(cfg: Config, overrides: Optional[dict] = None) -> Config:
    """``cfg`` with fields replaced by dotted paths from the top of :class:`~jaxgest.tgst.config.Config`:
    ``{"model.swap_similarity": "scaled", "train.autoencoder.mirror": False}``
    (:func:`jaxgest.runtime.config.apply_overrides`)."""
    return override_config(cfg, overrides, model="TGST")


def ae_optimizer(cfg: Config) -> optax.GradientTransformation:
    """The autoencoder's optimiser: Adam (§3.5) at :func:`ae_learning_rate`."""
    return optax.adam(ae_learning_rate(cfg))


def ae_learning_rate(cfg: Config):
    """The autoencoder's learning rate: ``cfg.train.autoencoder.learning_rate`` (constant, §3.5) or, with
    ``lr_schedule="cosine"``, a linear warm-up over the first 5 % of ``lr_decay_steps`` to it and a cosine
    decay to 10 % of it at ``lr_decay_steps`` (constant after)."""
    t = cfg.train.autoencoder
    if t.lr_schedule == "constant":
        return t.learning_rate
    n = max(int(t.lr_decay_steps), 2)
    return optax.warmup_cosine_decay_schedule(0.0, t.learning_rate, warmup_steps=max(1, n // 20),
                                              decay_steps=n, end_value=0.1 * t.learning_rate)


def transformer_optimizer(cfg: Config) -> optax.GradientTransformation:
    """The transformer's optimiser: Adam (§3.5) at ``cfg.train.transformer.learning_rate``."""
    return optax.adam(cfg.train.transformer.learning_rate)


# The two jitted steps, on bare states (:func:`jaxgest.runtime.training.bare_state`) with the optimiser built inside
# from the static config and compiled by :func:`jaxgest.runtime.training.jit_config_step`: jit's own cache serves
# every training of one config in a process (resume, tests); nothing is memoised here.

def _ae_step(state, batch, key, cfg: Config):
    tx = ae_optimizer(cfg)
    state, metrics = make_ae_train_step(cfg, tx)(state.replace(tx=tx), batch, key)
    return bare_state(state), metrics


def _transformer_step(state, batch, key, ae_params, cfg: Config):
    """:func:`jaxgest.tgst.steps.make_transformer_train_step` closes over the frozen autoencoder; here its
    parameters are a (replicated, not differentiated) argument, so one compilation serves every
    autoencoder (resumed runs, tests)."""
    tx = transformer_optimizer(cfg)
    state, metrics = make_transformer_train_step(cfg, tx, ae_params)(state.replace(tx=tx), batch, key)
    return bare_state(state), metrics


@functools.partial(jax.jit, static_argnames="cfg")
def _ae_heldout(params, batch, step, cfg: Config) -> dict:
    """The autoencoder step's metrics on a held-out batch (``--eval-every``)."""
    return ae_objective(params, batch, cfg)[1]


@functools.partial(jax.jit, static_argnames="cfg")
def _transformer_heldout(params, batch, step, ae_params, cfg: Config) -> dict:
    """The transformer step's metrics on a held-out batch (``--eval-every``)."""
    return transformer_objective(params, batch, ae_params, cfg)[1]


def _heldout_data(eval_data, cfg0: Config, cfg: Config, progress: bool):
    """The held-out clips of ``eval_data``: at least one (autoencoder) and two (transformer pairs) must hold
    the training windows of ``cfg``."""
    heldout = tdata.load_body_data(eval_data, cfg0, progress=progress)
    lengths = np.asarray(heldout.lengths)
    for what, need in (("autoencoder", 1), ("transformer", 2)):
        window = getattr(cfg.train, what).window
        if int((lengths >= window).sum()) < need:
            raise DataError(f"{eval_data}: the {what}'s held-out loss needs {need} clip(s) of at least "
                            f"{window} frames (its training window) at the model rate; the longest has "
                            f"{int(lengths.max())}")
    return heldout


def _profile_subdir(profile_dir, stage: str):
    return None if profile_dir is None else pathlib.Path(profile_dir) / stage


def _fixed_batches(batch_fn, mesh) -> list:
    return [parallel.sharded_batch_fn(batch_fn, mesh)(k) for k in range(training.EVAL_BATCHES)]


def _int32_step(state):
    """A non-weak int32 step so a restored state has the same avals (no recompilation)."""
    return state.replace(step=jnp.zeros((), jnp.int32))


def _check_batch(batch_size: int, mesh, what: str) -> None:
    if batch_size % mesh.size:
        raise JaxgestError(f"{what} batch size {batch_size} does not divide over {mesh.size} devices; "
                           "use --devices with a divisor of it")


def train(data_dir, workdir, *, preset: str = "tiny", ae_steps: Optional[int] = None,
          transformer_steps: Optional[int] = None, seed: int = 0, devices: Optional[int] = None,
          progress: bool = True, log_every: int = 50, ckpt_every: int = 500, ablate=(),
          overrides: Optional[dict] = None, eval_data=None, eval_every: Optional[int] = None, tb_dir=None,
          profile_dir=None) -> dict:
    """Train (or resume) both TGST stages on the dataset folder ``data_dir`` into ``workdir``; returns a
    summary dict.

    ``eval_data`` / ``eval_every``: each stage's loss on held-out clips
    (:data:`~jaxgest.runtime.training.EVAL_BATCHES` fixed batches of the training windows) every
    ``eval_every`` steps, logged as ``eval_loss``, ... (:func:`jaxgest.runtime.training.train_loop`);
    ``tb_dir``: TensorBoard events too; ``profile_dir``: a :func:`jax.profiler.trace` of a few steps of each
    stage (``profile_dir/autoencoder``, ``profile_dir/transformer``).

    Summary: ``{"workdir", "preset", "ae": {"steps", "start_step", "loss", "angle_deg", "wall_s",
    "steps_per_s"}, "transformer": {...same, with the loss terms}, "wall_s", "devices", "windows"}``.
    """
    t0 = time.perf_counter()
    parallel.maybe_initialize_distributed()
    cfg0 = apply_ablation(apply_overrides(resolve_preset(preset), overrides), ablate)
    ae_steps = cfg0.train.autoencoder.steps if ae_steps is None else int(ae_steps)
    transformer_steps = cfg0.train.transformer.steps if transformer_steps is None else int(transformer_steps)
    training.check_steps(ae_steps=ae_steps, transformer_steps=transformer_steps)
    training.check_intervals(log_every=log_every, ckpt_every=ckpt_every, eval_every=eval_every)
    training.check_eval(eval_data, eval_every, log_every)
    if data_dir is None:
        raise DataError("tgst train: no data folder given (the command line writes the built-in synthetic "
                        "data when --data is left out)")
    workdir = pathlib.Path(workdir)
    if workdir.exists() and not workdir.is_dir():
        raise DataError(f"{workdir}: exists and is not a directory")
    mesh = parallel.make_mesh(devices)
    info = parallel.device_info(mesh)

    body_data = tdata.load_body_data(data_dir, cfg0, progress=progress)
    cfg = tdata.fit_windows(cfg0, body_data)
    _check_batch(cfg.train.autoencoder.batch_size, mesh, "autoencoder")
    _check_batch(cfg.train.transformer.batch_size, mesh, "transformer")
    heldout = _heldout_data(eval_data, cfg0, cfg, progress) if eval_data is not None else None
    with exclusive_workdir(workdir, primary=jax.process_index() == 0):  # one writer per workdir
        workdir.mkdir(parents=True, exist_ok=True)

        # Check both stages' checkpoints before writing anything (another model must not load silently).
        ae_ckpt = ae_checkpointer(workdir, cfg.model)
        check_existing(ae_ckpt)
        stored_transformer = stored_transformer_meta(workdir, cfg.model, check=True)  # all but the AE step
        config_json = {"model": MODEL, "format_version": training.FORMAT_VERSION, "preset": preset,
                       "config": cfg.to_dict(), "data": str(pathlib.Path(data_dir)),
                       "data_summary": tdata.describe(body_data, cfg), "seed": int(seed), **info,
                       "skeleton": tdata.BODY_SIGNATURE, "code": provenance.code_stamp()}
        if jax.process_index() == 0:
            training.write_json_atomic(workdir / "config.json", config_json)

        key = jax.random.key(seed)
        params0 = jax.jit(init_params, static_argnames="cfg")(cfg=cfg.model, key=key)
        if cfg.model.autoencoder.standardize:  # frozen data statistics (a restored checkpoint brings its own)
            stats = tdata.channel_stats(body_data)
            params0 = dict(params0, autoencoder=dict(params0["autoencoder"], **{k: jnp.asarray(v)
                                                                               for k, v in stats.items()}))
        if cfg.model.autoencoder.linear_path and cfg.train.autoencoder.pca_init:  # start at the block PCA
            copies = 2 if cfg.train.autoencoder.mirror else 1
            params0 = dict(params0, autoencoder=autoencoder.init_linear_path(
                params0["autoencoder"], cfg.model.autoencoder, (body_data.upper + body_data.mirrored_upper)[
                    :copies * len(body_data.upper)], (body_data.lower + body_data.mirrored_lower)[
                    :copies * len(body_data.lower)], velocity_weight=cfg.train.autoencoder.init_velocity_weight))
        summary = {"workdir": str(workdir), "preset": preset, "devices": info["devices"],
                   "windows": {"ae": cfg.train.autoencoder.window, "transformer": cfg.train.transformer.window}}

        # ---- stage 1: autoencoder
        ae_step_fn = jit_config_step(_ae_step, mesh, cfg)
        ae_state = parallel.replicate(
            bare_state(_int32_step(create_ae_state(cfg, params0["autoencoder"], ae_optimizer(cfg)))), mesh)
        ae_state = ae_ckpt.restore(ae_state)
        tb = tb_dir if jax.process_index() == 0 else None
        ae_logger = training.MetricsLogger(workdir, extra={"stage": "autoencoder", **info}, tb_dir=tb)
        last = {}
        ae_eval = None
        if heldout is not None:
            fixed = _fixed_batches(lambda k: tdata.ae_batch(heldout, cfg, training.EVAL_SEED, k), mesh)
            ae_eval = training.heldout_eval(_ae_heldout, fixed, cfg)
        ae_state, summary["ae"] = _run_stage(
            ae_state, ae_step_fn, lambda i: tdata.ae_batch(body_data, cfg, seed, i), mesh,
            key=key, num_steps=ae_steps, checkpointer=ae_ckpt, logger=ae_logger, desc="tgst autoencoder",
            progress=progress, log_every=log_every, ckpt_every=ckpt_every, last=last, eval_fn=ae_eval,
            eval_every=eval_every, profile_dir=_profile_subdir(profile_dir, "autoencoder"))
        ae_done = int(jax.device_get(ae_state.step))
        ae_params = parallel.replicate(jax.device_get(ae_state.params), mesh)
        ae_ckpt.close()

        # ---- stage 2: transformer (autoencoder frozen, a step argument)
        summary["stale_transformer"] = set_aside_stale_transformer(workdir, stored_transformer, ae_done)
        tr_ckpt = transformer_checkpointer(workdir, cfg.model, ae_done)
        tr_step_fn = jit_config_step(_transformer_step, mesh, cfg, extra_args=1)
        tr_state = create_transformer_state(cfg, params0["transformer"], transformer_optimizer(cfg))
        tr_state = parallel.replicate(bare_state(_int32_step(tr_state)), mesh)
        tr_state = tr_ckpt.restore(tr_state)
        tr_logger = training.MetricsLogger(workdir, extra={"stage": "transformer", **info}, tb_dir=tb)
        tr_eval = None
        if heldout is not None:
            fixed = _fixed_batches(
                lambda k: tdata.transformer_batch(heldout, cfg, training.EVAL_SEED, k), mesh)
            tr_eval = training.heldout_eval(_transformer_heldout, fixed, ae_params, cfg)
        tr_state, summary["transformer"] = _run_stage(
            tr_state, lambda st, b, k: tr_step_fn(st, b, k, ae_params),
            lambda i: tdata.transformer_batch(body_data, cfg, seed, i), mesh, key=key,
            num_steps=transformer_steps, checkpointer=tr_ckpt, logger=tr_logger, desc="tgst transformer",
            progress=progress, log_every=log_every, ckpt_every=ckpt_every, last={}, eval_fn=tr_eval,
            eval_every=eval_every, profile_dir=_profile_subdir(profile_dir, "transformer"))
        tr_ckpt.close()
        summary["wall_s"] = time.perf_counter() - t0
        return summary


def _run_stage(state, step_fn, batch_fn, mesh, *, key, num_steps, checkpointer, logger, desc, progress,
               log_every, ckpt_every, last, eval_fn=None, eval_every=None, profile_dir=None):
    start = int(jax.device_get(state.step))
    t = time.perf_counter()
    try:
        if start < num_steps:
            state = training.train_loop(
                state, step_fn, parallel.sharded_batch_fn(batch_fn, mesh),
                key=key, num_steps=num_steps, checkpointer=checkpointer, logger=logger,
                log_every=min(log_every, num_steps), ckpt_every=ckpt_every, desc=desc, progress=progress,
                on_log=lambda s, m: last.update(m), eval_fn=eval_fn,
                eval_every=eval_every if eval_fn is not None else None, profile_dir=profile_dir)
    finally:
        logger.close()
    wall = time.perf_counter() - t
    done = int(jax.device_get(state.step))
    ran = max(done - start, 0)
    out = {"steps": done, "start_step": start, "wall_s": wall, "steps_per_s": ran / wall if ran and wall else 0.0}
    out.update({k: v for k, v in last.items() if k != "steps_per_s"})
    return state, out


def format_summary(s: dict) -> str:
    """One line for the CLI."""
    def part(name, d):
        if d["steps"] == d["start_step"]:
            done = "no steps requested" if d["steps"] == 0 else f"already at step {d['steps']}, nothing to do"
            return f"{name} {done}"
        extra = f" ({d['angle_deg']:.2f} deg)" if "angle_deg" in d else ""
        extra += f" (held-out {d['eval_loss']:.4g})" if "eval_loss" in d else ""
        return (f"{name} {d['steps']} steps loss {d.get('loss', float('nan')):.4g}{extra}, "
                f"{d['steps_per_s']:.1f} steps/s (from step {d['start_step']})")
    stale = (f" (the transformer trained on the earlier autoencoder was moved to checkpoints/"
             f"{s['stale_transformer']} and retrained)" if s.get("stale_transformer") else "")
    return (f"tgst train ({s['preset']}, {s['devices']} device(s), windows {s['windows']['ae']}/"
            f"{s['windows']['transformer']}): {part('autoencoder', s['ae'])}; "
            f"{part('transformer', s['transformer'])}{stale}; {s['wall_s']:.1f} s -> {s['workdir']}")

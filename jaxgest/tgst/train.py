"""Train TGST: stage 1 the motion autoencoder, stage 2 the style transformer with the autoencoder frozen.

``train(data_dir, workdir, preset=...)`` is what ``jaxgest tgst train`` calls. Layout of a workdir::

    config.json                      preset, effective config (windows fitted to the data), data, devices
    metrics.jsonl                    one line per log step: {"stage", "step", "loss", ..., "devices", ...}
    checkpoints/autoencoder/<step>   orbax {params, opt_state, step} + meta (kind tgst_autoencoder)
    checkpoints/transformer/<step>   the same for the transformer (kind tgst_transformer)

Both stages use optax Adam (§3.5), one jit-compiled step each (:func:`jaxgest.parallel.parallelize_step`,
state donated, batch split over the devices) and :func:`jaxgest.training.train_loop` (NaN stop, tqdm,
checkpoints). A run resumes from the latest checkpoint of each stage; a finished autoencoder is not
retrained. The transformer's checkpoint records the autoencoder step it was trained on: resuming it on a
different autoencoder raises CheckpointError (use a new workdir).

Default step counts (``DEFAULT_STEPS``): tiny 200 + 200; paper 10,000 + 10,000 (about the paper's 1000
epochs of its 21 min of AE data in batches of 32 x 256 frames, and of its 63 content/style pairs in batches
of 8). References: Kuriyama et al. 2022, §3.5, §4.1.
"""

from __future__ import annotations

import dataclasses
import functools
import pathlib
import time
from typing import Optional

import jax
import jax.numpy as jnp
import optax

from jaxgest import parallel, training
from jaxgest.errors import DataError, JaxgestError
from jaxgest.motion.synthetic.dataset import training_folder
from jaxgest.tgst import data as tdata
from jaxgest.tgst.config import (ADDED_AUTOENCODER_FIELDS, ADDED_FIELDS, ADDED_TRANSFORMER_FIELDS, AutoencoderConfig,
                                 TGSTConfig, TransformerConfig, get_config, with_stored_defaults)
from jaxgest.tgst.model import init_params
from jaxgest.tgst.steps import (create_ae_state, create_transformer_state, make_ae_train_step,
                                make_transformer_train_step)

DEFAULT_STEPS = {"tiny": (200, 200), "paper": (10_000, 10_000), "fit": (6_000, 10_000)}
AE_KIND, TRANSFORMER_KIND = "tgst_autoencoder", "tgst_transformer"
AE_SUBDIR, TRANSFORMER_SUBDIR = "checkpoints/autoencoder", "checkpoints/transformer"
PRESETS = tuple(DEFAULT_STEPS)


def resolve_preset(preset: str) -> TGSTConfig:
    if preset not in PRESETS:
        raise JaxgestError(f"unknown TGST preset {preset!r} (choose from {', '.join(PRESETS)})")
    return get_config(preset)


LOSS_TERMS = ("identity", "cyclic", "structure", "appearance")
#: config keys the autoencoder does not depend on: a stage-1 checkpoint can be shared by runs that differ only
#: in them (the loss ablations of Table 4 reuse one autoencoder)
AE_IGNORED = ("steps", "name", "transformer", "transformer_learning_rate", "transformer_batch_size",
              "transformer_window", "swap_temperature", "swap_similarity") + tuple(f"use_{t}" for t in LOSS_TERMS) + tuple(
              f"lambda_{t}" for t in LOSS_TERMS)


def apply_ablation(cfg: TGSTConfig, ablate=()) -> TGSTConfig:
    """``cfg`` with the named transformer loss terms switched off (paper Table 4); clear error otherwise."""
    ablate = tuple(ablate or ())
    unknown = [a for a in ablate if a not in LOSS_TERMS]
    if unknown:
        raise JaxgestError(f"unknown loss term {unknown[0]!r} to ablate (choose from {', '.join(LOSS_TERMS)})")
    if set(ablate) == set(LOSS_TERMS):
        raise JaxgestError("cannot ablate every loss term: the transformer would have nothing to learn")
    return dataclasses.replace(cfg, **{f"use_{a}": False for a in ablate})


def apply_overrides(cfg: TGSTConfig, overrides: Optional[dict] = None) -> TGSTConfig:
    """``cfg`` with fields replaced: ``{"swap_similarity": "scaled", "transformer.token_positions": "none"}``
    (``autoencoder.`` / ``transformer.`` prefixes reach the sub-configs); for experiments and ablations."""
    top, subs = {}, {"autoencoder": {}, "transformer": {}}
    for key, value in (overrides or {}).items():
        head, _, rest = key.partition(".")
        if rest and head in subs:
            subs[head][rest] = value
        else:
            top[key] = value
    for name, fields in subs.items():
        if fields:
            top[name] = dataclasses.replace(getattr(cfg, name), **fields)
    try:
        return dataclasses.replace(cfg, **top)
    except (TypeError, ValueError) as e:
        raise JaxgestError(f"bad TGST config override: {e}") from None


def _legacy_compatible(ckpt: training.Checkpointer) -> training.Checkpointer:
    """Let a checkpoint written before some config fields existed match a config that has them at their class
    defaults (the old behaviour, see :func:`jaxgest.tgst.config.with_stored_defaults`): such fields are left
    out of the requested config when the stored one lacks them. Any other value still is a mismatch."""
    if not ckpt.directory.is_dir() or ckpt.latest_step() is None:
        return ckpt
    stored = (ckpt.stored_meta() or {}).get("config") or {}
    req = ckpt.meta["config"]
    for name in ADDED_FIELDS:
        if name not in stored and name in req and req[name] == getattr(TGSTConfig, name):
            del req[name]
    for sub, cls, added in (("autoencoder", AutoencoderConfig, ADDED_AUTOENCODER_FIELDS),
                            ("transformer", TransformerConfig, ADDED_TRANSFORMER_FIELDS)):
        if isinstance(req.get(sub), dict) and isinstance(stored.get(sub), dict):
            for name in added:
                if name not in stored[sub] and req[sub].get(name, object()) == getattr(cls, name):
                    del req[sub][name]
    return ckpt


def ae_checkpointer(workdir, cfg: TGSTConfig, read_only: bool = False) -> training.Checkpointer:
    return _legacy_compatible(training.Checkpointer(
        workdir, kind=AE_KIND, config=dataclasses.asdict(cfg), skeleton=tdata.BODY_SIGNATURE, subdir=AE_SUBDIR,
        read_only=read_only, ignore=AE_IGNORED))


def transformer_checkpointer(workdir, cfg: TGSTConfig, ae_step: Optional[int],
                             read_only: bool = False) -> training.Checkpointer:
    config = dict(dataclasses.asdict(cfg), autoencoder_step=ae_step)
    ignore = ("steps",) if ae_step is not None else ("steps", "autoencoder_step")
    return _legacy_compatible(training.Checkpointer(
        workdir, kind=TRANSFORMER_KIND, config=config, skeleton=tdata.BODY_SIGNATURE, subdir=TRANSFORMER_SUBDIR,
        read_only=read_only, ignore=ignore))


@functools.lru_cache(maxsize=None)
def _jitted_init():
    return jax.jit(init_params, static_argnames="cfg")


@functools.lru_cache(maxsize=8)
def compiled_ae_step(cfg: TGSTConfig, mesh):
    """The jit-compiled, data-parallel autoencoder step of ``cfg`` on ``mesh`` and its optimizer.

    Memoised so several trainings in one process (resume, tests) compile each step once.
    """
    tx = optax.adam(ae_learning_rate(cfg))
    return parallel.parallelize_step(make_ae_train_step(cfg, tx), mesh), tx


def ae_learning_rate(cfg: TGSTConfig):
    """The autoencoder's learning rate: ``cfg.ae_learning_rate`` (constant, §3.5) or, with
    ``ae_lr_schedule="cosine"``, a linear warm-up over the first 5 % of ``ae_lr_decay_steps`` to it and a
    cosine decay to 10 % of it at ``ae_lr_decay_steps`` (constant after)."""
    if cfg.ae_lr_schedule == "constant":
        return cfg.ae_learning_rate
    n = max(int(cfg.ae_lr_decay_steps), 2)
    return optax.warmup_cosine_decay_schedule(0.0, cfg.ae_learning_rate, warmup_steps=max(1, n // 20),
                                              decay_steps=n, end_value=0.1 * cfg.ae_learning_rate)


@functools.lru_cache(maxsize=8)
def compiled_transformer_step(cfg: TGSTConfig, mesh):
    """The jit-compiled transformer step ``(state, batch, key, ae_params) -> (state, metrics)`` and tx.

    :func:`jaxgest.tgst.steps.make_transformer_train_step` closes over the frozen autoencoder; here the
    autoencoder parameters are a (replicated, not differentiated) argument instead, so one compilation
    serves every autoencoder (resumed runs, tests). Same shardings as
    :func:`jaxgest.parallel.parallelize_step`, state donated.
    """
    tx = optax.adam(cfg.transformer_learning_rate)

    def step(state, batch, key, ae_params):
        return make_transformer_train_step(cfg, tx, ae_params)(state, batch, key)

    rep, data = parallel.replicated(mesh), parallel.data_sharding(mesh)
    jitted = jax.jit(step, in_shardings=(rep, data, rep, rep), out_shardings=(rep, rep), donate_argnums=(0,))
    return jitted, tx


def _int32_step(state):
    """A non-weak int32 step so a restored state has the same avals (no recompilation)."""
    return state.replace(step=jnp.zeros((), jnp.int32))


def _check_existing(ckpt: training.Checkpointer) -> None:
    stored = ckpt.stored_meta()
    if stored is not None:
        ckpt.check_meta(stored)


def _check_batch(batch_size: int, mesh, what: str) -> None:
    if batch_size % mesh.size:
        raise JaxgestError(f"{what} batch size {batch_size} does not divide over {mesh.size} devices; "
                           "use --devices with a divisor of it")


def train(data_dir, workdir, *, preset: str = "tiny", ae_steps: Optional[int] = None,
          transformer_steps: Optional[int] = None, seed: int = 0, devices: Optional[int] = None,
          progress: bool = True, log_every: int = 50, ckpt_every: int = 500, ablate=(),
          overrides: Optional[dict] = None) -> dict:
    """Train (or resume) both TGST stages on ``data_dir`` (None: the built-in synthetic data, written to
    ``workdir/synthetic-data``) into ``workdir``; returns a summary dict.

    Summary: ``{"workdir", "preset", "ae": {"steps", "start_step", "loss", "angle_deg", "wall_s",
    "steps_per_s"}, "transformer": {...same, with the loss terms}, "wall_s", "devices", "windows"}``.
    """
    t0 = time.perf_counter()
    parallel.maybe_initialize_distributed()
    cfg0 = apply_ablation(apply_overrides(resolve_preset(preset), overrides), ablate)
    d_ae, d_tr = DEFAULT_STEPS[preset]
    ae_steps = d_ae if ae_steps is None else int(ae_steps)
    transformer_steps = d_tr if transformer_steps is None else int(transformer_steps)
    training.check_steps(ae_steps=ae_steps, transformer_steps=transformer_steps)
    training.check_intervals(log_every=log_every, ckpt_every=ckpt_every)
    workdir = pathlib.Path(workdir)
    if workdir.exists() and not workdir.is_dir():
        raise DataError(f"{workdir}: exists and is not a directory")
    data_dir = training_folder(data_dir, workdir, progress)  # None: the built-in synthetic data
    mesh = parallel.make_mesh(devices)
    info = parallel.device_info(mesh)

    body_data = tdata.load_body_data(data_dir, cfg0, progress=progress)
    cfg = tdata.fit_windows(cfg0, body_data)
    cfg = with_stored_defaults(cfg, _stored_config(workdir, cfg))  # a workdir of an older version
    _check_batch(cfg.ae_batch_size, mesh, "autoencoder")
    _check_batch(cfg.transformer_batch_size, mesh, "transformer")
    workdir.mkdir(parents=True, exist_ok=True)

    # Check both stages' checkpoints before writing anything (another preset must not load silently).
    ae_ckpt = ae_checkpointer(workdir, cfg)
    _check_existing(ae_ckpt)
    stored_transformer = _stored_transformer_meta(workdir, cfg, check=True)  # all but the autoencoder step
    config_json = {"kind": "tgst", "format_version": training.FORMAT_VERSION, "preset": preset,
                   "config": dataclasses.asdict(cfg), "data": str(pathlib.Path(data_dir)),
                   "data_summary": tdata.describe(body_data, cfg), "seed": int(seed), **info,
                   "skeleton": tdata.BODY_SIGNATURE}
    if jax.process_index() == 0:
        training.write_json_atomic(workdir / "config.json", config_json)

    key = jax.random.PRNGKey(seed)
    params0 = _jitted_init()(cfg=cfg, key=key)
    if cfg.autoencoder.standardize:  # frozen data statistics (a restored checkpoint brings its own)
        stats = tdata.channel_stats(body_data)
        params0 = dict(params0, autoencoder=dict(params0["autoencoder"], **{k: jnp.asarray(v)
                                                                           for k, v in stats.items()}))
    summary = {"workdir": str(workdir), "preset": preset, "devices": info["devices"],
               "windows": {"ae": cfg.ae_window, "transformer": cfg.transformer_window}}

    # ---- stage 1: autoencoder
    ae_step_fn, tx_ae = compiled_ae_step(cfg, mesh)
    ae_state = parallel.replicate(_int32_step(create_ae_state(cfg, params0["autoencoder"], tx_ae)), mesh)
    ae_state = ae_ckpt.restore(ae_state)
    ae_logger = training.MetricsLogger(workdir, extra={"stage": "autoencoder", **info})
    last = {}
    ae_state, summary["ae"] = _run_stage(
        ae_state, ae_step_fn, lambda i: tdata.ae_batch(body_data, cfg, seed, i), mesh,
        key=key, num_steps=ae_steps, checkpointer=ae_ckpt, logger=ae_logger, desc="tgst autoencoder",
        progress=progress, log_every=log_every, ckpt_every=ckpt_every, last=last)
    ae_done = int(jax.device_get(ae_state.step))
    ae_params = parallel.replicate(jax.device_get(ae_state.params), mesh)
    ae_ckpt.close()

    # ---- stage 2: transformer (autoencoder frozen, closed over by the step)
    summary["stale_transformer"] = set_aside_stale_transformer(workdir, stored_transformer, ae_done)
    tr_ckpt = transformer_checkpointer(workdir, cfg, ae_done)
    tr_step_fn, tx_tr = compiled_transformer_step(cfg, mesh)
    tr_state = parallel.replicate(
        _int32_step(create_transformer_state(cfg, params0["transformer"], tx_tr)), mesh)
    tr_state = tr_ckpt.restore(tr_state)
    tr_logger = training.MetricsLogger(workdir, extra={"stage": "transformer", **info})
    tr_state, summary["transformer"] = _run_stage(
        tr_state, lambda st, b, k: tr_step_fn(st, b, k, ae_params),
        lambda i: tdata.transformer_batch(body_data, cfg, seed, i), mesh, key=key,
        num_steps=transformer_steps, checkpointer=tr_ckpt, logger=tr_logger, desc="tgst transformer",
        progress=progress, log_every=log_every, ckpt_every=ckpt_every, last={})
    tr_ckpt.close()
    summary["wall_s"] = time.perf_counter() - t0
    return summary


def _stored_config(workdir, cfg: TGSTConfig) -> Optional[dict]:
    """The config dict stored with the latest autoencoder checkpoint of ``workdir`` (None without one)."""
    if not (pathlib.Path(workdir) / AE_SUBDIR).is_dir():
        return None
    probe = ae_checkpointer(workdir, cfg, read_only=True)
    try:
        stored = probe.stored_meta()
        return None if stored is None else stored.get("config")
    finally:
        probe.close()


def _stored_transformer_meta(workdir, cfg: TGSTConfig, check: bool = False) -> Optional[dict]:
    """The stored meta of the transformer checkpoint (None without one); ``check``: raise on a config mismatch
    other than the autoencoder step."""
    if not (pathlib.Path(workdir) / TRANSFORMER_SUBDIR).is_dir():
        return None
    probe = transformer_checkpointer(workdir, cfg, None, read_only=True)
    try:
        stored = probe.stored_meta()
        if check and stored is not None:
            probe.check_meta(stored)
        return stored
    finally:
        probe.close()


def set_aside_stale_transformer(workdir, stored: Optional[dict], ae_step: int) -> Optional[str]:
    """Move a transformer checkpoint trained on another autoencoder step out of the way (renamed, not deleted)
    so the transformer retrains on the current autoencoder; returns the new folder name, or None.

    stored: the transformer checkpoint's meta as read before training (:func:`_stored_transformer_meta`)."""
    old = (stored or {}).get("config", {}).get("autoencoder_step")
    if stored is None or old is None or int(old) == int(ae_step):
        return None
    src = pathlib.Path(workdir).resolve() / TRANSFORMER_SUBDIR
    dst = src.with_name(f"{src.name}.autoencoder-step-{old}")
    k = 1
    while dst.exists():
        k += 1
        dst = src.with_name(f"{src.name}.autoencoder-step-{old}.{k}")
    if jax.process_index() == 0:
        src.rename(dst)
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("tgst: stale transformer set aside")
    return dst.name


def _run_stage(state, step_fn, batch_fn, mesh, *, key, num_steps, checkpointer, logger, desc, progress,
               log_every, ckpt_every, last):
    start = int(jax.device_get(state.step))
    t = time.perf_counter()
    if start < num_steps:
        state = training.train_loop(
            state, step_fn, parallel.sharded_batch_fn(batch_fn, mesh),
            key=key, num_steps=num_steps, checkpointer=checkpointer, logger=logger,
            log_every=min(log_every, num_steps), ckpt_every=ckpt_every, desc=desc, progress=progress,
            on_log=lambda s, m: last.update(m))
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
        return (f"{name} {d['steps']} steps loss {d.get('loss', float('nan')):.4g}{extra}, "
                f"{d['steps_per_s']:.1f} steps/s (from step {d['start_step']})")
    stale = (f" (the transformer trained on the earlier autoencoder was moved to checkpoints/"
             f"{s['stale_transformer']} and retrained)" if s.get("stale_transformer") else "")
    return (f"tgst train ({s['preset']}, {s['devices']} device(s), windows {s['windows']['ae']}/"
            f"{s['windows']['transformer']}): {part('autoencoder', s['ae'])}; "
            f"{part('transformer', s['transformer'])}{stale}; {s['wall_s']:.1f} s -> {s['workdir']}")

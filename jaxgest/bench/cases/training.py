"""Training-step cases: one optimiser step of each model at its preset's batch size.

* ``train_tgst_autoencoder``: :func:`jaxgest.tgst.steps.make_ae_train_step` (Adam), ``paper`` preset,
  batch ``ae_batch_size`` (32) x ``ae_window`` (256) frames of 39 upper + 24 lower exp-map channels.
* ``train_tgst_transformer``: :func:`jaxgest.tgst.steps.make_transformer_train_step` (Adam, autoencoder
  frozen), ``paper`` preset, batch ``transformer_batch_size`` (8) content/style pairs of
  ``transformer_window`` (1280) frames each.
* ``train_zeggs_paper`` (full run) / ``train_zeggs_tiny`` (``--quick``): :func:`jaxgest.zeggs.steps.
  make_train_step` (RAdam, dropout on, generator on its own predictions over the whole window) at the
  preset's batch (paper: 32 sequences of T = 256 frames, style clips of ``style_window_max`` = 512 frames).
  The paper step takes seconds per call on 2 cores, so ``--quick`` times the ``tiny`` preset instead; the
  record's ``case`` and ``note`` name the preset. Compiled with the preset's ``compiler_options`` as
  ``jaxgest zeggs train`` does (tiny: XLA backend optimisation level 0; paper: XLA's defaults).

Each call is one full step ``(state, batch, key) -> (state, metrics)`` on the same input state (no buffer
donation, so repeated calls are independent); ``frames`` is the target window and ``per_pose_us`` the
step time per target frame in the batch. Random weights (``init`` of the model, or LeCun-normal random
for ZEGGS, see :func:`jaxgest.bench.cases.zeggs.random_params`) and random inputs of the right shapes.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax.training.train_state import TrainState

from jaxgest.bench.harness import Case, Impl
from jaxgest.tgst import model as TM
from jaxgest.tgst import steps as TS
from jaxgest.tgst.config import preset as tgst_config
from jaxgest.zeggs import steps as ZS
from jaxgest.zeggs.config import preset as zeggs_config
from jaxgest.zeggs.model import ZeggsModel


@functools.lru_cache(maxsize=None)
def _tgst_params():
    return jax.jit(lambda k: TM.init_params(tgst_config("paper").model, k))(jax.random.key(0))


def _f32(rng, shape, scale=1.0):
    return jnp.asarray(rng.normal(scale=scale, size=shape), jnp.float32)


def tgst_ae_case() -> Case:
    cfg = tgst_config("paper")
    tx = optax.adam(cfg.train.autoencoder.learning_rate)
    b, f = cfg.train.autoencoder.batch_size, cfg.train.autoencoder.window

    def make_args():
        state = TS.create_ae_state(cfg, _tgst_params()["autoencoder"], tx)
        rng = np.random.default_rng(1)
        batch = {"upper": _f32(rng, (b, f, cfg.model.autoencoder.upper_channels), 0.4),
                 "lower": _f32(rng, (b, f, cfg.model.autoencoder.lower_channels), 0.4)}
        return state, batch, jax.random.key(0)

    return Case(name="train_tgst_autoencoder", batch=b, frames=f,
                impls=[Impl("jit", jax.jit(TS.make_ae_train_step(cfg, tx)), kind="jit")], make_args=make_args,
                note=f"TGST paper autoencoder, Adam step, batch {b} x {f} frames")


def tgst_transformer_case() -> Case:
    cfg = tgst_config("paper")
    tx = optax.adam(cfg.train.transformer.learning_rate)
    b, f = cfg.train.transformer.batch_size, cfg.train.transformer.window

    def step(state, batch, key, ae_params):
        # ae_params as an argument (as jaxgest.tgst.trainer does): a closed-over pytree would be baked into
        # the executable as constants and inflate the compile time.
        return TS.make_transformer_train_step(cfg, tx, ae_params)(state, batch, key)

    def make_args():
        p = _tgst_params()
        state = TS.create_transformer_state(cfg, p["transformer"], tx)
        rng = np.random.default_rng(2)
        c = cfg.model.autoencoder.upper_channels
        batch = {"content": _f32(rng, (b, f, c), 0.4), "style": _f32(rng, (b, f, c), 0.4)}
        return state, batch, jax.random.key(0), p["autoencoder"]

    return Case(name="train_tgst_transformer", batch=b, frames=f,
                impls=[Impl("jit", jax.jit(step), kind="jit")], make_args=make_args,
                note=f"TGST paper style transformer (autoencoder frozen), Adam step, batch {b} content/style "
                     f"pairs of {f} frames")


def zeggs_batch(cfg, batch: int, window: int, style_frames: int, seed: int = 3) -> dict:
    """A random batch with the layout of :meth:`jaxgest.zeggs.data.ZeggsData.batch`."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(batch, window, 4)) * np.array([1.0, 0.0, 0.05, 0.0]) + np.array([1.0, 0, 0, 0])
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    mask = np.ones((batch, style_frames), bool)
    mask[: batch // 2, style_frames * 3 // 4:] = False  # half the clips shorter: the masked path is timed
    return {
        "speech": _f32(rng, (batch, window, cfg.speech_dim)),
        "pose": _f32(rng, (batch, window, cfg.pose_dim), 0.5),
        "root_position": _f32(rng, (batch, window, 3), 10.0),
        "root_rotation": jnp.asarray(q, jnp.float32),
        "style": _f32(rng, (batch, style_frames, cfg.pose_dim), 0.5),
        "style_mask": jnp.asarray(mask),
        "facing": jnp.asarray(np.tile([0.0, 0.0, 1.0], (batch, 1)), jnp.float32),
    }


def zeggs_train_case(preset: str, *, quick: bool) -> Case:
    from jaxgest.bench.cases.zeggs import random_params

    cfg = zeggs_config(preset)
    tx = ZS.make_optimizer(cfg)
    b, f, s = cfg.train.batch_size, cfg.train.window, cfg.train.style_window_max
    stats = ZS.pose_stats(cfg.model)

    def make_args():
        state = TrainState.create(apply_fn=ZeggsModel(cfg.model).apply, params=random_params(cfg.model), tx=tx)
        return state, zeggs_batch(cfg.model, b, f, s), jax.random.key(0), stats

    return Case(name=f"train_zeggs_{preset}", batch=b, frames=f,
                impls=[Impl("jit", jax.jit(ZS.make_train_step(cfg), compiler_options=cfg.train.compiler_options),
                            kind="jit")], make_args=make_args,
                quick=quick, max_repeats_slow=2,
                note=f"ZEGGS {preset} preset, RAdam step, batch {b} x {f} frames, style clips of {s} frames, "
                     f"compiler options {cfg.train.compiler_options}")


def cases(quick: bool) -> list:
    out = [tgst_ae_case(), tgst_transformer_case()]
    out.append(zeggs_train_case("tiny", quick=True) if quick else zeggs_train_case("paper", quick=False))
    return out

"""The full ZeroEGGS model, its optimiser and the pure training step.

Batch layout (float32 unless said; produced by :meth:`jaxgest.zeggs.data.ZeggsData.batch`)::

    speech        (B, T, 81)  normalised speech features
    pose          (B, T, P)   normalised target pose features, P = 15 j + 6 (frame 0 seeds the generator)
    root_position (B, T, 3)   target root positions (cm), relative to the window's first root
    root_rotation (B, T, 4)   target root yaw quaternions (w, x, y, z), relative to the window's first root
    style         (B, S, P)   normalised style pose features, padded at the end
    style_mask    (B, S)      bool, True on real style frames
    facing        (B, 3)      world target facing direction (ground plane, unit) in the window's frame

``make_train_step(cfg, tx, pose_mean=..., pose_std=...)`` returns ``step(state, batch, key) -> (state,
metrics)``, to be wrapped as ``jax.jit(step, donate_argnums=(0,))``. The key is folded with the step
number inside; it drives dropout and the reparameterised style sample. ``pose_mean`` / ``pose_std``
``(P,)`` are the per-channel dataset statistics used to normalise ``pose`` and ``style`` (closed over as
constants): the generator denormalises its predictions with them (outputs are per channel) to integrate the
root and the losses work on denormalised features; pose *inputs* (the style clip, the generator's pose
state) are rescaled to one std per feature group (``generator.input_scale``, ``cfg.input_norm``).
Metrics: ``loss``, ``recon``, ``kl``, ``kl_weight`` and every reconstruction term (batch means).

References: Ghorbani et al. 2023, §3 (Fig. 2) and §4.3 (RAdam 1e-4, decay 0.995 every 1k steps, no
teacher forcing, KL annealing).
"""

from __future__ import annotations

import functools
from typing import Callable, Optional

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax.training.train_state import TrainState

from jaxgest.zeggs import losses as L
from jaxgest.zeggs.config import ZeggsConfig
from jaxgest.zeggs.generator import Generator, input_scale
from jaxgest.zeggs.speech_encoder import SpeechEncoder
from jaxgest.training import make_update_step
from jaxgest.zeggs.style_encoder import StyleEncoder, sample_style

Step = Callable[[TrainState, dict, jax.Array], tuple[TrainState, dict]]


class ZeggsModel(nn.Module):
    """Speech encoder + style encoder (VAE) + generator; params ``{speech_encoder, style_encoder, generator}``.

    References: Ghorbani et al. 2023, §3 (Fig. 2).
    """

    cfg: ZeggsConfig

    def setup(self):
        self.speech_encoder = SpeechEncoder(self.cfg)
        self.style_encoder = StyleEncoder(self.cfg)
        self.generator = Generator(self.cfg)

    def encode_speech(self, speech, *, deterministic: bool = True):
        """``(B, T, 81)`` -> speech embeddings ``(B, T, D_S)``."""
        return self.speech_encoder(speech, deterministic=deterministic)

    def encode_style(self, style, mask=None, *, deterministic: bool = True):
        """``(B, S, P)`` (+ mask) -> ``(mu, logvar)`` each ``(B, D_e)``."""
        return self.style_encoder(style, mask, deterministic=deterministic)

    def generate(self, speech_embedding, style_embedding, pose0, root_position0, root_rotation0, facing,
                 pose_mean=None, pose_std=None):
        """Run the generator (see :class:`jaxgest.zeggs.generator.Generator`)."""
        return self.generator(pose0, root_position0, root_rotation0, facing, speech_embedding, style_embedding,
                              pose_mean, pose_std)

    def __call__(self, speech, style, style_mask, pose0, root_position0, root_rotation0, facing, sample_key,
                 pose_mean=None, pose_std=None, *, temperature: float = 1.0, deterministic: bool = True):
        """Everything: ``(output dict of the generator, aux)`` with aux = mu, logvar, style/speech embeddings."""
        s = self.encode_speech(speech, deterministic=deterministic)
        mu, logvar = self.encode_style(style, style_mask, deterministic=deterministic)
        e = sample_style(mu, logvar, sample_key, temperature)
        out = self.generate(s, e, pose0, root_position0, root_rotation0, facing, pose_mean, pose_std)
        return out, {"mu": mu, "logvar": logvar, "style_embedding": e, "speech_embedding": s}


def dummy_inputs(cfg: ZeggsConfig, batch: int = 1, frames: int = 4, style_frames: Optional[int] = None):
    """Zero arrays of the model's input shapes (for ``init`` / ``eval_shape``)."""
    S = style_frames or max(frames, cfg.style_min_frames)
    q = np.zeros((batch, 4), np.float32)
    q[:, 0] = 1.0
    return (jnp.zeros((batch, frames, cfg.speech_dim)), jnp.zeros((batch, S, cfg.pose_dim)),
            jnp.ones((batch, S), bool), jnp.zeros((batch, cfg.pose_dim)), jnp.zeros((batch, 3)), jnp.asarray(q),
            jnp.zeros((batch, 3)).at[:, 2].set(1.0))


def _init(cfg: ZeggsConfig, key: jax.Array):
    k_init, k_sample = jax.random.split(key)
    return ZeggsModel(cfg).init({"params": k_init}, *dummy_inputs(cfg), k_sample)["params"]


@functools.lru_cache(maxsize=16)
def _init_jit(cfg: ZeggsConfig):
    return jax.jit(functools.partial(_init, cfg), compiler_options=cfg.compiler_options)


def init_params(cfg: ZeggsConfig, key: jax.Array):
    """Freshly initialised parameters ``{"speech_encoder", "style_encoder", "generator"}``.

    Called eagerly, one jitted function per config (cached, compiled with ``cfg.compiler_options``):
    repeated calls with the same config compile once. Under a trace (``jit``, ``eval_shape``) it is traced
    inline.
    """
    if isinstance(key, jax.core.Tracer):
        return _init(cfg, key)
    return _init_jit(cfg)(key)


@functools.lru_cache(maxsize=16)
def make_optimizer(cfg: ZeggsConfig) -> optax.GradientTransformation:
    """RAdam with learning rate ``lr * decay ** (step // decay_steps)`` (staircase exponential decay).

    Cached per config: the same object for the same config, so train states built from it have equal
    tree structures (their compiled steps can be reused).

    References: Ghorbani et al. 2023, §4.3 (Liu et al. 2019 RAdam, 1e-4, x0.995 every 1k iterations).
    """
    schedule = optax.exponential_decay(cfg.learning_rate, transition_steps=cfg.lr_decay_steps,
                                       decay_rate=cfg.lr_decay, staircase=True)
    return optax.radam(schedule)


def create_train_state(cfg: ZeggsConfig, key: jax.Array, tx: optax.GradientTransformation) -> TrainState:
    """TrainState with fresh parameters (``apply_fn = ZeggsModel(cfg).apply``)."""
    return TrainState.create(apply_fn=ZeggsModel(cfg).apply, params=init_params(cfg, key), tx=tx)


def _stats(cfg: ZeggsConfig, pose_mean, pose_std):
    mean = np.zeros(cfg.pose_dim, np.float32) if pose_mean is None else np.asarray(pose_mean, np.float32)
    std = np.ones(cfg.pose_dim, np.float32) if pose_std is None else np.asarray(pose_std, np.float32)
    if mean.shape != (cfg.pose_dim,) or std.shape != (cfg.pose_dim,):
        raise ValueError(f"pose_mean/pose_std must have shape ({cfg.pose_dim},), got {mean.shape}, {std.shape}")
    return jnp.asarray(mean), jnp.asarray(std)


def loss_terms(params, batch: dict, key: jax.Array, step, *, cfg: ZeggsConfig, pose_mean: jax.Array,
               pose_std: jax.Array, deterministic: bool = False) -> dict[str, jax.Array]:
    """Per-example loss terms ``(B,)``: ``loss`` (eq. 1), ``recon`` (eq. 2), ``kl``, and each MAE term."""
    B, T, P = batch["pose"].shape
    chex.assert_shape(batch["speech"], (B, T, cfg.speech_dim))
    chex.assert_shape(batch["root_position"], (B, T, 3))
    chex.assert_shape(batch["root_rotation"], (B, T, 4))
    chex.assert_shape(batch["facing"], (B, 3))
    k_drop, k_sample = jax.random.split(key)
    style = batch["style"] * input_scale(cfg, pose_mean, pose_std)[None, None]  # style inputs: group normalisation
    out, aux = ZeggsModel(cfg).apply(
        {"params": params}, batch["speech"], style, batch["style_mask"], batch["pose"][:, 0],
        batch["root_position"][:, 0], batch["root_rotation"][:, 0], batch["facing"], k_sample, pose_mean, pose_std,
        deterministic=deterministic, rngs={"dropout": k_drop})
    mean, std = pose_mean[None, None], pose_std[None, None]
    terms = L.reconstruction_terms(
        out["pose"] * std + mean, out["root_position"], out["root_rotation"],
        batch["pose"] * std + mean, batch["root_position"], batch["root_rotation"], cfg=cfg)
    kl = L.kl_divergence(aux["mu"], aux["logvar"], reduction=cfg.kl_reduction)
    w = L.kl_weight(step, center=cfg.kl_center, growth=cfg.kl_growth, cap=cfg.kl_cap)
    loss = L.total_loss(terms, kl, w, cfg=cfg)
    recon = L.total_loss(terms, jnp.zeros_like(kl), w, cfg=cfg)
    return {"loss": loss, "recon": recon, "kl": kl, "kl_weight": jnp.broadcast_to(w, kl.shape), **terms}


def make_train_step(cfg: ZeggsConfig, tx: optax.GradientTransformation, *, pose_mean=None,
                    pose_std=None) -> Step:
    """``step(state, batch, key) -> (state, metrics)``: one RAdam step on the negative ELBO (eq. 1).

    The generator runs on its own predictions (no teacher forcing); dropout is on.
    References: Ghorbani et al. 2023, §4.3.
    """
    mean, std = _stats(cfg, pose_mean, pose_std)

    def loss_fn(params, batch, key, step):
        terms = loss_terms(params, batch, key, step, cfg=cfg, pose_mean=mean, pose_std=std)
        metrics = {k: jnp.mean(v) for k, v in terms.items()}
        return metrics["loss"], metrics

    del tx  # the state's own optimiser applies the update
    return make_update_step(loss_fn, fold_in_step=True)

"""ZeroEGGS loss terms, optimiser and the pure training step (built by :func:`jaxgest.runtime.training.make_update_step`).

Batch layout (float32 unless said; produced by :meth:`jaxgest.zeggs.data.ZeggsData.batch`)::

    speech        (B, T, 81)  normalised speech features
    pose          (B, T, P)   normalised target pose features, P = 15 j + 6 (frame 0 seeds the generator)
    root_position (B, T, 3)   target root positions (cm), relative to the window's first root
    root_rotation (B, T, 4)   target root yaw quaternions (w, x, y, z), relative to the window's first root
    style         (B, S, P)   normalised style pose features, padded at the end
    style_mask    (B, S)      bool, True on real style frames
    facing        (B, 3)      world target facing direction (ground plane, unit) in the window's frame

``make_train_step(cfg)`` (``cfg`` a :class:`jaxgest.zeggs.config.Config`) returns ``step(state, batch, key,
pose_stats) -> (state, metrics)``, to be wrapped as ``jax.jit(step, donate_argnums=(0,))``. The key is
folded with the step number inside; it drives dropout and the reparameterised style sample.
``pose_stats = {"mean", "std"}`` ``(P,)`` are the per-channel dataset statistics used to normalise ``pose``
and ``style``; they are arguments (not constants), so one compilation serves any statistics of that shape:
the generator denormalises its predictions with them (outputs are per channel) to integrate the root and
the losses work on denormalised features; pose *inputs* (the style clip, the generator's pose state) are
rescaled to one std per feature group (``generator.input_scale``, ``cfg.model.input_norm``).
Metrics: ``loss``, ``recon``, ``kl``, ``kl_weight`` and every reconstruction term (batch means).

References: Ghorbani et al. 2023, §3 (Fig. 2) and §4.3 (RAdam 1e-4, decay 0.995 every 1k steps, no
teacher forcing, KL annealing).
"""

from __future__ import annotations

from typing import Callable

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax.training.train_state import TrainState

from jaxgest.runtime.training import make_update_step
from jaxgest.zeggs import losses
from jaxgest.zeggs.config import Config, ModelConfig
from jaxgest.zeggs.generator import input_scale
from jaxgest.zeggs.model import ZeggsModel

Step = Callable[[TrainState, dict, jax.Array, dict], tuple[TrainState, dict]]


def make_optimizer(cfg: Config) -> optax.GradientTransformation:
    """RAdam with learning rate ``lr * decay ** (step // decay_steps)`` (staircase exponential decay).

    References: Ghorbani et al. 2023, §4.3 (Liu et al. 2019 RAdam, 1e-4, x0.995 every 1k iterations).
    """
    return optax.radam(learning_rate_schedule(cfg))


def learning_rate_schedule(cfg: Config) -> optax.Schedule:
    """The staircase exponential decay of :func:`make_optimizer` (``cfg.train``'s rate, decay and period)."""
    t = cfg.train
    return optax.exponential_decay(t.learning_rate, transition_steps=t.lr_decay_steps, decay_rate=t.lr_decay,
                                   staircase=True)


def pose_stats(cfg: ModelConfig, mean=None, std=None) -> dict[str, jax.Array]:
    """``{"mean", "std"}`` ``(P,)`` float32 (default: zeros and ones), shape-checked against the model."""
    mean = np.zeros(cfg.pose_dim, np.float32) if mean is None else np.asarray(mean, np.float32)
    std = np.ones(cfg.pose_dim, np.float32) if std is None else np.asarray(std, np.float32)
    if mean.shape != (cfg.pose_dim,) or std.shape != (cfg.pose_dim,):
        raise ValueError(f"pose_mean/pose_std must have shape ({cfg.pose_dim},), got {mean.shape}, {std.shape}")
    return {"mean": jnp.asarray(mean), "std": jnp.asarray(std)}


def initial_pose_swaps(key: jax.Array, probability: float, batch_size: int) -> jax.Array:
    """Which rows ``(B,)`` bool of a batch start the generator from a replaced pose (independently, each
    with ``probability``); all False at 0 (the paper). The draw of :func:`initial_poses` with the same key."""
    if probability <= 0.0:
        return jnp.zeros((batch_size,), bool)
    return jax.random.bernoulli(key, probability, (batch_size,))


def initial_poses(pose: jax.Array, key: jax.Array, probability: float, source: str = "row",
                  swap: jax.Array | None = None) -> jax.Array:
    """The generator's initial poses ``(B, P)`` of a batch of targets ``pose (B, T, P)``: each row's own
    first frame, or with ``probability`` (independently per row, :func:`initial_pose_swaps`) a replaced one:
    ``source="row"`` the first frame of the previous row of the batch (``jnp.roll`` by one; a batch of one
    keeps its own), ``"mean"`` the data's mean pose (zeros: ``pose`` is normalised). ``probability`` 0 is the
    paper (training starts from the target's own first pose, §4.3); above 0 the initial pose no longer tells
    the generator the target's style reliably, so the style must come from the embedding
    (``initial_pose_shuffle``, an experiment of ``experiments/zeggs_synthetic``, not the paper).
    ``swap`` ``(B,)`` bool: the rows to replace, when the caller has drawn them already (the draw of
    :func:`initial_pose_swaps` with ``key``; :func:`loss_terms` passes it, so the mask and the start agree).
    """
    own = pose[:, 0]
    if probability <= 0.0:
        return own
    if swap is None:
        swap = initial_pose_swaps(key, probability, pose.shape[0])
    other = jnp.roll(own, 1, axis=0) if source == "row" else jnp.zeros_like(own)
    return jnp.where(swap[:, None], other, own)


def initial_pose_frame_weight(swap: jax.Array, window: int, frames: int) -> jax.Array | None:
    """Per-frame loss weights ``(B, T)``: 0 on the first ``frames`` frames of a swapped row, 1 elsewhere
    (``None`` when nothing is left out). At most ``T - 2`` frames go, so every row keeps a finite difference.
    The move from a replaced initial pose to the target's has no target of its own
    (``initial_pose_mask_seconds``; an experiment, not the paper).

    What is left out is each masked frame's own terms (and every finite difference that touches it), so the
    loss does not depend on the target there. The prediction over those frames still matters downstream:
    the generator integrates its root velocity from the first frame, so a root drift made on masked frames
    carries into the root and world terms (``root_position``, ``world_*``, ``facing``) of later, kept frames.
    Weights are 0/1 and each term is a per-row mean over the kept frames (:func:`jaxgest.zeggs.losses.mae`),
    so a masked row weighs as much as an unmasked one in the batch mean, and logged loss values of masked
    runs are means over fewer frames (not comparable term by term with unmasked runs)."""
    frames = min(int(frames), window - 2)
    if frames <= 0:
        return None
    head = jnp.arange(window)[None, :] < frames
    return jnp.where(swap[:, None] & head, 0.0, 1.0).astype(jnp.float32)


def loss_terms(params, batch: dict, key: jax.Array, step, *, cfg: Config, pose_mean: jax.Array,
               pose_std: jax.Array, deterministic: bool = False) -> dict[str, jax.Array]:
    """Per-example loss terms ``(B,)``: ``loss`` (eq. 1), ``recon`` (eq. 2), ``kl``, and each MAE term."""
    B, T, P = batch["pose"].shape
    m, t = cfg.model, cfg.train
    chex.assert_shape(batch["speech"], (B, T, m.speech_dim))
    chex.assert_shape(batch["root_position"], (B, T, 3))
    chex.assert_shape(batch["root_rotation"], (B, T, 4))
    chex.assert_shape(batch["facing"], (B, 3))
    k_drop, k_sample = jax.random.split(key)
    # the shuffle's key is folded from the step key, so dropout and the style sample draw the same as without it
    k_pose0 = jax.random.fold_in(key, 0x1_5E)
    swap = initial_pose_swaps(k_pose0, t.initial_pose_shuffle, B)
    if t.initial_pose_source == "row" and B == 1:  # rolling a batch of one keeps its own pose
        swap = jnp.zeros_like(swap)
    pose0 = initial_poses(batch["pose"], k_pose0, t.initial_pose_shuffle, t.initial_pose_source, swap=swap)
    masked = round(t.initial_pose_mask_seconds * m.fps) if t.initial_pose_shuffle > 0 else 0
    frame_weight = initial_pose_frame_weight(swap, T, masked)
    style = batch["style"] * input_scale(m, pose_mean, pose_std)[None, None]  # style inputs: group normalisation
    out, aux = ZeggsModel(m).apply(
        {"params": params}, batch["speech"], style, batch["style_mask"], pose0,
        batch["root_position"][:, 0], batch["root_rotation"][:, 0], batch["facing"], k_sample, pose_mean, pose_std,
        deterministic=deterministic, rngs={"dropout": k_drop})
    mean, std = pose_mean[None, None], pose_std[None, None]
    terms = losses.reconstruction_terms(
        out["pose"] * std + mean, out["root_position"], out["root_rotation"],
        batch["pose"] * std + mean, batch["root_position"], batch["root_rotation"], cfg=m, frame_weight=frame_weight)
    kl = losses.kl_divergence(aux["mu"], aux["logvar"], reduction=t.kl_reduction)
    w = losses.kl_weight(step, center=t.kl_center, growth=t.kl_growth, cap=t.kl_cap)
    loss = losses.total_loss(terms, kl, w, cfg=t)
    recon = losses.total_loss(terms, jnp.zeros_like(kl), w, cfg=t)
    return {"loss": loss, "recon": recon, "kl": kl, "kl_weight": jnp.broadcast_to(w, kl.shape), **terms}


def make_train_step(cfg: Config) -> Step:
    """``step(state, batch, key, pose_stats) -> (state, metrics)``: one RAdam step on the negative ELBO (eq. 1).

    The generator runs on its own predictions (no teacher forcing); dropout is on. ``pose_stats``:
    :func:`pose_stats` (an argument, so one compilation serves every dataset with that pose size).
    References: Ghorbani et al. 2023, §4.3.
    """
    def step(state, batch, key, stats):
        def loss_fn(params, batch, key, step):
            terms = loss_terms(params, batch, key, step, cfg=cfg, pose_mean=stats["mean"], pose_std=stats["std"])
            metrics = {k: jnp.mean(v) for k, v in terms.items()}
            return metrics["loss"], metrics

        return make_update_step(loss_fn, fold_in_step=True)(state, batch, key)

    return step

"""Pure training steps of the TGST autoencoder and style transformer.

Both builders return ``step(state, batch, key) -> (state, metrics)`` to be wrapped with
``jax.jit(step, donate_argnums=(0,))``. ``state`` is a ``flax.training.train_state.TrainState`` (re-exported
by ``jaxgest.training``) holding only the parameters being trained; the optimizer update uses the ``tx``
given to the builder (it must be the state's ``tx``). Neither model uses dropout (§3.5: "no dropout"), so
the steps are deterministic and ``key`` is accepted for the common step signature only.

The transformer step trains with the autoencoder frozen: its parameters are *closed over* by
:func:`make_transformer_train_step` (23,743 constants in the compiled step), so the state, optimizer and
checkpoint of the transformer contain the transformer alone. Mirroring of style clips (augmentation) is
done by the data pipeline, not here.

Metrics are scalars: ``loss`` plus every term separately.
References: Kuriyama et al. 2022, §3.5.
"""

from __future__ import annotations

from typing import Callable

import chex
import jax
import jax.numpy as jnp
import optax
from flax.training.train_state import TrainState

from jaxgest.tgst.autoencoder import expmap_reconstruction_loss, mean_angular_error_deg
from jaxgest.tgst.config import TGSTConfig
from jaxgest.tgst.model import (Params, autoencoder_module, encode_pair, reconstruct, transformer_loss_terms,
                                transformer_module)
from jaxgest.tgst.tokens import tokenize
from jaxgest.training import make_update_step

Step = Callable[[TrainState, dict, jax.Array], tuple[TrainState, dict]]


def create_ae_state(cfg: TGSTConfig, ae_params: Params, tx: optax.GradientTransformation) -> TrainState:
    """TrainState of the autoencoder (``apply_fn`` = ``MotionAutoencoder.apply``)."""
    return TrainState.create(apply_fn=autoencoder_module(cfg).apply, params=ae_params, tx=tx)


def create_transformer_state(cfg: TGSTConfig, tr_params: Params,
                             tx: optax.GradientTransformation) -> TrainState:
    """TrainState of the style transformer (``apply_fn`` = ``StyleTransformer.apply``)."""
    return TrainState.create(apply_fn=transformer_module(cfg).apply, params=tr_params, tx=tx)


def ae_loss_terms(ae_params: Params, batch: dict, *, cfg: TGSTConfig) -> dict[str, jax.Array]:
    """Per-example autoencoder losses ``(batch,)``: ``loss`` over all 21 joints, upper/lower parts, degrees.

    batch: ``{"upper": (B, F, 39), "lower": (B, F, 24)}`` with F a multiple of 4 (the encoder's stride).
    Each window goes through the same clip-end handling as a whole clip at transfer time
    (:func:`jaxgest.tgst.model.reconstruct`: replicate-padded at both ends, trimmed back); without edge
    frames (``cfg.edge_frames == 0``, old runs) the window is encoded as it is.
    """
    upper, lower = batch["upper"], batch["lower"]
    chex.assert_rank([upper, lower], 3)
    b, f, _ = upper.shape
    chex.assert_shape(lower, (b, f, cfg.autoencoder.lower_channels))
    if cfg.edge_frames:
        up_hat, lo_hat = reconstruct(ae_params, upper, cfg=cfg)
    else:
        (up_hat, lo_hat), _ = autoencoder_module(cfg).apply({"params": ae_params}, upper)
        up_hat, lo_hat = up_hat[:, :f], lo_hat[:, :f]
    pred = jnp.concatenate([up_hat, lo_hat], axis=-1)
    target = jnp.concatenate([upper, lower], axis=-1)
    return {
        "loss": expmap_reconstruction_loss(pred, target),
        "upper_loss": expmap_reconstruction_loss(up_hat, upper),
        "lower_loss": expmap_reconstruction_loss(lo_hat, lower),
        "angle_deg": jax.lax.stop_gradient(mean_angular_error_deg(pred, target)),
    }


def make_ae_train_step(cfg: TGSTConfig, tx: optax.GradientTransformation) -> Step:
    """Adam step on the mean exp-map reconstruction loss (§3.5); batch ``{"upper", "lower"}``."""

    del tx  # the state's own optimiser applies the update

    def loss_fn(params, batch, key, step):
        del key, step  # deterministic model (no dropout), constant loss weights
        terms = ae_loss_terms(params, batch, cfg=cfg)
        metrics = {k: jnp.mean(v) for k, v in terms.items()}
        return metrics["loss"], metrics

    return make_update_step(loss_fn)


def make_transformer_train_step(cfg: TGSTConfig, tx: optax.GradientTransformation, ae_params: Params) -> Step:
    """Adam step on eq. 12 with the autoencoder ``ae_params`` frozen (closed over).

    batch: ``{"content": (B, Fc, 39), "style": (B, Fs, 39)}`` upper-body exp-maps of unaligned clips (any
    lengths >= 16 frames; encoded like :func:`jaxgest.tgst.model.transfer_arrays` encodes them: the content
    with its edge padding, the style cut to its real frames). Metrics: ``loss``, ``identity``, ``cyclic``,
    ``structure``, ``appearance`` (batch means; switched-off terms are 0).
    """
    ae_params = jax.tree_util.tree_map(jnp.asarray, ae_params)
    w, h = cfg.token_width, cfg.token_stride

    del tx  # the state's own optimiser applies the update

    def loss_fn(params, batch, key, step):
        del key, step  # deterministic model (no dropout), constant loss weights
        zc, zs, _, _ = encode_pair(ae_params, batch["content"], batch["style"], cfg=cfg)
        content, style = (jax.lax.stop_gradient(tokenize(z, w, h)) for z in (zc, zs))
        terms = transformer_loss_terms(params, content, style, cfg=cfg)
        metrics = {k: jnp.mean(v) for k, v in terms.items()}
        return metrics["loss"], metrics

    return make_update_step(loss_fn)

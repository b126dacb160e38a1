"""Pure training steps of the TGST autoencoder and style transformer (losses: :mod:`jaxgest.tgst.losses`).

Both builders take the whole preset (:class:`~jaxgest.tgst.config.Config`: the model and the stage's
training settings) and return ``step(state, batch, key) -> (state, metrics)`` to be wrapped with
``jax.jit(step, donate_argnums=(0,))``. ``state`` is a ``flax.training.train_state.TrainState`` (re-exported
by ``jaxgest.runtime.training``) holding only the parameters being trained; the optimizer update uses the ``tx``
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

from jaxgest.motion import body
from jaxgest.tgst.autoencoder import TRUNK_JOINTS
from jaxgest.tgst.config import Config
from jaxgest.tgst.losses import ae_loss_terms, transformer_loss_terms  # noqa: F401  (ae_loss_terms re-exported)
from jaxgest.tgst.model import Params, autoencoder_module, encode_pair, transformer_module
from jaxgest.tgst.tokens import tokenize
from jaxgest.runtime.training import make_update_step

Step = Callable[[TrainState, dict, jax.Array], tuple[TrainState, dict]]


def create_ae_state(cfg: Config, ae_params: Params, tx: optax.GradientTransformation) -> TrainState:
    """TrainState of the autoencoder (``apply_fn`` = ``MotionAutoencoder.apply``)."""
    return TrainState.create(apply_fn=autoencoder_module(cfg.model).apply, params=ae_params, tx=tx)


def create_transformer_state(cfg: Config, tr_params: Params,
                             tx: optax.GradientTransformation) -> TrainState:
    """TrainState of the style transformer (``apply_fn`` = ``StyleTransformer.apply``)."""
    return TrainState.create(apply_fn=transformer_module(cfg.model).apply, params=tr_params, tx=tx)


def make_ae_train_step(cfg: Config, tx: optax.GradientTransformation) -> Step:
    """Adam step on the mean exp-map reconstruction loss (§3.5), plus ``train.autoencoder.velocity_weight`` times
    the exp-map frame-to-frame difference term and ``train.autoencoder.position_velocity_weight`` times the
    joint-displacement term when they are set, and the trunk joints' errors ``train.autoencoder.trunk_weight``
    times (not in the paper); batch ``{"upper", "lower"}``."""

    del tx  # the state's own optimiser applies the update

    def loss_fn(params, batch, key, step):
        del key, step  # deterministic model (no dropout), constant loss weights
        return ae_objective(params, batch, cfg)

    return make_update_step(loss_fn)


def ae_objective(params: Params, batch: dict, cfg: Config) -> tuple[jax.Array, dict]:
    """``(objective, metrics)`` of the autoencoder step (:func:`make_ae_train_step`) on ``batch``: the
    objective it differentiates and the batch means it logs (``loss`` is the reconstruction term); the
    held-out loss (``--eval-every``) is the same metrics on held-out windows."""
    t = cfg.train.autoencoder  # optional recipe terms (not in the paper)
    terms = ae_loss_terms(params, batch, cfg=cfg.model, position_terms=bool(t.position_velocity_weight),
                          trunk_terms=t.trunk_weight != 1.0)
    metrics = {k: jnp.mean(v) for k, v in terms.items()}
    loss = metrics["loss"]
    if t.velocity_weight:
        loss = loss + t.velocity_weight * metrics["velocity_loss"]
    if t.trunk_weight != 1.0:  # the trunk's share of both terms counted trunk_weight times
        extra = metrics["trunk_loss"] + t.velocity_weight * metrics["trunk_velocity_loss"]
        loss = loss + (t.trunk_weight - 1.0) * (len(TRUNK_JOINTS) / len(body.BODY)) * extra
    if t.position_velocity_weight:
        term = "position_velocity_loss" if t.position_velocity_joints == "all" else "upper_position_velocity_loss"
        loss = loss + t.position_velocity_weight * metrics[term]
    return loss, metrics


def make_transformer_train_step(cfg: Config, tx: optax.GradientTransformation, ae_params: Params) -> Step:
    """Adam step on eq. 12 (weights ``cfg.train.transformer``) with the autoencoder ``ae_params`` frozen
    (closed over).

    batch: ``{"content": (B, Fc, 39), "style": (B, Fs, 39)}`` upper-body exp-maps of unaligned clips (any
    lengths >= 16 frames; encoded like :func:`jaxgest.tgst.model.transfer_arrays` encodes them: the content
    with its edge padding, the style cut to its real frames), optionally ``"style_valid": (B, Ns)`` bool, the
    real tokens of style clips padded to a common length (``style_tokens="clip_and_mirror"``,
    :func:`jaxgest.tgst.data.transformer_batch`). Metrics: ``loss``, ``identity``, ``cyclic``,
    ``structure``, ``appearance`` (batch means; switched-off terms are 0).
    """
    ae_params = jax.tree_util.tree_map(jnp.asarray, ae_params)

    del tx  # the state's own optimiser applies the update

    def loss_fn(params, batch, key, step):
        del key, step  # deterministic model (no dropout), constant loss weights
        return transformer_objective(params, batch, ae_params, cfg)

    return make_update_step(loss_fn)


def transformer_objective(params: Params, batch: dict, ae_params: Params,
                          cfg: Config) -> tuple[jax.Array, dict]:
    """``(loss, metrics)`` of the transformer step (:func:`make_transformer_train_step`) on ``batch`` with the
    frozen autoencoder ``ae_params``; the held-out loss (``--eval-every``) is the same on held-out pairs."""
    model, weights = cfg.model, cfg.train.transformer
    w, h = model.token_width, model.token_stride
    zc, zs, _, _ = encode_pair(ae_params, batch["content"], batch["style"], cfg=model)
    content, style = (jax.lax.stop_gradient(tokenize(z, w, h)) for z in (zc, zs))
    style_valid = batch.get("style_valid")  # whole style clips padded to a common length
    if style_valid is not None:
        chex.assert_shape(style_valid, style.shape[:2])
    terms = transformer_loss_terms(params, content, style, cfg=model, train=weights, style_valid=style_valid)
    metrics = {k: jnp.mean(v) for k, v in terms.items()}
    return metrics["loss"], metrics

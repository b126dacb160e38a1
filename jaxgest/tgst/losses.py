"""Losses of both TGST stages. Pure functions returning per-example values ``(batch,)``.

* the style transformer's terms, eqs. 5-12 (:func:`identity_loss` ... :func:`total_transformer_loss`), and
  their evaluation on a batch of tokens (:func:`transformer_loss_terms`);
* the autoencoder's per-batch terms (:func:`ae_loss_terms`); its reconstruction loss itself lives with the
  autoencoder (``autoencoder.expmap_reconstruction_loss``).

References: Kuriyama et al. 2022, §3.5, eqs. 5-12 (and the authors' public code for the reductions).
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp

from jaxgest.nn import safe_norm
from jaxgest.tgst import model as M
from jaxgest.tgst.autoencoder import (expmap_reconstruction_loss, expmap_velocity_loss, mean_angular_error_deg,
                                      position_velocity_errors, position_velocity_loss,
                                      trunk_channels)
from jaxgest.tgst.config import ModelConfig, TransformerTrainConfig

Params = M.Params

_EPS = 1e-8


def token_norm(x: jax.Array, valid=None) -> jax.Array:
    """||x||_tau: the L2 norm of every token averaged over tokens; ``(batch, N, d) -> (batch,)``.

    valid: optional ``(batch, N)`` bool; the average is then over the real tokens of a padded set only.
    References: Kuriyama et al. 2022, §3.5 ("averaged L2-norm computed per each token").
    """
    chex.assert_rank(x, 3)
    if valid is None:
        return jnp.mean(safe_norm(x), axis=1)
    chex.assert_shape(valid, x.shape[:2])
    v = valid.astype(x.dtype)
    return jnp.sum(safe_norm(x) * v, axis=1) / jnp.maximum(jnp.sum(v, axis=1), 1.0)


def identity_loss(content_identity: jax.Array, content_tokens: jax.Array, style_identity: jax.Array,
                  style_tokens: jax.Array, style_valid=None) -> jax.Array:
    """L_identity = ||g^{c|c} - g^c||_tau + ||g^{s|s} - g^s||_tau; ``(batch,)``.

    content_identity: content transferred with itself as style ``(batch, Nc, d)``; likewise for style.
    style_valid: optional ``(batch, Ns)`` bool of the real tokens of a padded style set.
    References: Kuriyama et al. 2022, eq. 5.
    """
    chex.assert_equal_shape([content_identity, content_tokens])
    chex.assert_equal_shape([style_identity, style_tokens])
    return token_norm(content_identity - content_tokens) + token_norm(style_identity - style_tokens, style_valid)


def cyclic_loss(cyclic_tokens: jax.Array, content_tokens: jax.Array) -> jax.Array:
    """L_cyclic = ||g^{c|s|c} - g^c||_tau (content -> style -> back with the content as style); ``(batch,)``.

    References: Kuriyama et al. 2022, eqs. 6-8.
    """
    chex.assert_equal_shape([cyclic_tokens, content_tokens])
    return token_norm(cyclic_tokens - content_tokens)


def structure_matrix(keys: jax.Array) -> jax.Array:
    """m(g): cosine self-similarity of encoder keys, ``(batch, N, d) -> (batch, N, N)``.

    ``keys`` are the gesture-token keys k_i = m_k g_i of the encoder (CLS excluded, as in docs/design.md; the
    authors' code computes the matrix with CLS and then drops its row and column, which is the same).
    References: Kuriyama et al. 2022, eq. 9.
    """
    chex.assert_rank(keys, 3)
    unit = keys / jnp.maximum(safe_norm(keys)[..., None], _EPS)
    return jnp.einsum("bid,bjd->bij", unit, unit)


def structure_loss(content_keys: jax.Array, transferred_keys: jax.Array) -> jax.Array:
    """L_structure = ||m(g^c) - m(g^{s|c})||_F; keys ``(batch, N, d)`` each -> ``(batch,)``.

    References: Kuriyama et al. 2022, eq. 10.
    """
    chex.assert_equal_shape([content_keys, transferred_keys])
    diff = structure_matrix(content_keys) - structure_matrix(transferred_keys)
    return safe_norm(diff.reshape(diff.shape[0], -1))


def appearance_loss(style_cls: jax.Array, transferred_cls: jax.Array) -> jax.Array:
    """L_appearance = ||CLS^s - CLS^{s|c}||_2 of encoder CLS outputs ``(batch, d)`` -> ``(batch,)``.

    References: Kuriyama et al. 2022, eq. 11.
    """
    chex.assert_equal_shape([style_cls, transferred_cls])
    chex.assert_rank(style_cls, 2)
    return safe_norm(style_cls - transferred_cls)


def total_transformer_loss(identity: jax.Array, cyclic: jax.Array, structure: jax.Array,
                           appearance: jax.Array,
                           *, lambda_identity: float = 1.0, lambda_cyclic: float = 1.0,
                           lambda_structure: float = 1.0, lambda_appearance: float = 1.0,
                           use_identity: bool = True, use_cyclic: bool = True, use_structure: bool = True,
                           use_appearance: bool = True) -> jax.Array:
    """L = L_identity + lambda_c L_cyclic + lambda_s L_structure + lambda_a L_appearance (shape of the terms).

    Each term has a weight (identity's is 1 in the paper) and a switch (ablation, Table 4); a switched-off
    term contributes exactly nothing (not even a NaN).
    References: Kuriyama et al. 2022, eq. 12.
    """
    terms = [(identity, lambda_identity, use_identity), (cyclic, lambda_cyclic, use_cyclic),
             (structure, lambda_structure, use_structure), (appearance, lambda_appearance, use_appearance)]
    active = [w * t for t, w, on in terms if on]
    if not active:
        raise ValueError("every transformer loss term is switched off")
    total = active[0]
    for t in active[1:]:
        total = total + t
    return total


def transformer_loss_terms(tr_params: Params, content_tokens: jax.Array, style_tokens: jax.Array, *,
                           cfg: ModelConfig, train: TransformerTrainConfig,
                           style_valid=None) -> dict[str, jax.Array]:
    """Per-example loss terms ``(batch,)`` of eqs. 5-11 and their weighted sum (eq. 12) under ``"loss"``.

    content_tokens, style_tokens: raw tokens ``(batch, N, d)``. ``train`` gives the weights and switches of
    eq. 12; switched-off terms are not computed and reported as zeros. style_valid: optional ``(batch, Ns)``
    bool of the real tokens of style sets padded to a common length (whole style clips of different lengths):
    padded tokens are never attended to, get no swap weight and are left out of the style identity term, so
    the terms equal those of the unpadded sets.
    References: Kuriyama et al. 2022, eqs. 5-12.
    """
    sv = style_valid
    enc_c, aux_c = M.transformer_encode(tr_params, content_tokens, cfg=cfg)
    enc_s, aux_s = M.transformer_encode(tr_params, style_tokens, cfg=cfg, valid=sv)
    transferred, _ = M.swap_encoded(tr_params, enc_c, enc_s, style_tokens, cfg=cfg, style_valid=sv)  # eq. 4
    zeros = jnp.zeros(content_tokens.shape[:1], content_tokens.dtype)
    terms = {"identity": zeros, "cyclic": zeros, "structure": zeros, "appearance": zeros}
    if train.use_identity:  # eq. 5: each clip transferred with itself as style
        c_id, _ = M.swap_encoded(tr_params, enc_c, enc_c, content_tokens, cfg=cfg)
        s_id, _ = M.swap_encoded(tr_params, enc_s, enc_s, style_tokens, cfg=cfg, style_valid=sv)
        terms["identity"] = identity_loss(c_id, content_tokens, s_id, style_tokens, sv)
    if train.use_cyclic or train.use_structure or train.use_appearance:
        enc_x, aux_x = M.transformer_encode(tr_params, transferred, cfg=cfg)
        if train.use_cyclic:  # eqs. 6-8: back-transfer with the content as style
            cyc, _ = M.swap_encoded(tr_params, enc_x, enc_c, content_tokens, cfg=cfg)
            terms["cyclic"] = cyclic_loss(cyc, content_tokens)
        if train.use_structure:  # eqs. 9-10
            terms["structure"] = structure_loss(aux_c["keys"], aux_x["keys"])
        if train.use_appearance:  # eq. 11
            terms["appearance"] = appearance_loss(aux_s["cls"], aux_x["cls"])
    terms["loss"] = total_transformer_loss(
        terms["identity"], terms["cyclic"], terms["structure"], terms["appearance"],
        lambda_identity=train.lambda_identity, lambda_cyclic=train.lambda_cyclic,
        lambda_structure=train.lambda_structure, lambda_appearance=train.lambda_appearance,
        use_identity=train.use_identity, use_cyclic=train.use_cyclic, use_structure=train.use_structure,
        use_appearance=train.use_appearance)
    return terms


def ae_loss_terms(ae_params: Params, batch: dict, *, cfg: ModelConfig,
                  position_terms: bool = True, trunk_terms: bool = False) -> dict[str, jax.Array]:
    """Per-example autoencoder losses ``(batch,)``: ``loss`` over all 21 joints, upper/lower parts, degrees.

    ``position_terms``: also the joint-displacement terms (``position_velocity_loss`` and its upper-body
    version; forward kinematics of the decoded and the input poses, about a third of a training step's time),
    which the training step asks for only when ``train.autoencoder.position_velocity_weight`` is set.
    ``trunk_terms``: also the reconstruction and frame-to-frame terms of the trunk joints alone
    (``TRUNK_JOINTS``), for ``train.autoencoder.trunk_weight``.

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
        up_hat, lo_hat = M.reconstruct(ae_params, upper, cfg=cfg)
    else:
        (up_hat, lo_hat), _ = M.autoencoder_module(cfg).apply({"params": ae_params}, upper)
        up_hat, lo_hat = up_hat[:, :f], lo_hat[:, :f]
    pred = jnp.concatenate([up_hat, lo_hat], axis=-1)
    target = jnp.concatenate([upper, lower], axis=-1)
    terms = {
        "loss": expmap_reconstruction_loss(pred, target),
        "upper_loss": expmap_reconstruction_loss(up_hat, upper),
        "lower_loss": expmap_reconstruction_loss(lo_hat, lower),
        "velocity_loss": expmap_velocity_loss(pred, target),  # frame-to-frame change (optional recipe term)
        "angle_deg": jax.lax.stop_gradient(mean_angular_error_deg(pred, target)),
    }
    if trunk_terms:  # the trunk's rotations alone (optional recipe term)
        ch = trunk_channels()
        terms["trunk_loss"] = expmap_reconstruction_loss(up_hat[..., ch], upper[..., ch])
        terms["trunk_velocity_loss"] = expmap_velocity_loss(up_hat[..., ch], upper[..., ch])
    if position_terms:  # frame-to-frame joint displacement, cm (optional recipe term)
        pv_errors = position_velocity_errors(up_hat, lo_hat, upper, lower)
        terms["position_velocity_loss"] = position_velocity_loss(pv_errors)
        terms["upper_position_velocity_loss"] = position_velocity_loss(pv_errors, "upper")
    return terms

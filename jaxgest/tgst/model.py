"""TGST as pure functions of parameter pytrees: init, encode/decode, token transfer, training loss terms.

``params = {"autoencoder": <MotionAutoencoder params>, "transformer": <StyleTransformer params>}`` (plain
Flax ``params`` collections). Every function takes ``cfg`` (a hashable :class:`TGSTConfig`) as a keyword
so it can be a jit static argument: ``jax.jit(transfer_arrays, static_argnames=("cfg", "method"))``.

References: Kuriyama et al. 2022, §3 (Fig. 2 data flow), §4.3 (baselines).
"""

from __future__ import annotations

import math
from typing import Any

import chex
import jax
import jax.numpy as jnp

from jaxgest.tgst import baselines, losses, swap
from jaxgest.tgst.autoencoder import MotionAutoencoder
from jaxgest.tgst.config import TGSTConfig
from jaxgest.tgst.tokens import detokenize, pad_frames, tokenize, trim_frames
from jaxgest.tgst.transformer import StyleTransformer

METHODS = ("soft", "hard", "adain", "avatarnet")
Params = dict[str, Any]


def autoencoder_module(cfg: TGSTConfig) -> MotionAutoencoder:
    return MotionAutoencoder(cfg.autoencoder)


def transformer_module(cfg: TGSTConfig) -> StyleTransformer:
    return StyleTransformer(cfg.transformer)


def init_params(cfg: TGSTConfig, key: jax.Array) -> Params:
    """Fresh parameters ``{"autoencoder": ..., "transformer": ...}`` for ``cfg``."""
    k_ae, k_tr = jax.random.split(key)
    frames = cfg.frame_multiple
    ae = autoencoder_module(cfg).init(k_ae, jnp.zeros((1, frames, cfg.autoencoder.upper_channels)))
    tokens = jnp.zeros((1, 3, cfg.transformer.token_dim))
    tr = transformer_module(cfg).init(k_tr, tokens, tokens)
    return {"autoencoder": ae["params"], "transformer": tr["params"]}


def encode(ae_params: Params, upper: jax.Array, *, cfg: TGSTConfig) -> jax.Array:
    """Upper-body exp-maps ``(batch, F, 39)`` -> latents ``(batch, ceil(F / 4), 16)``."""
    return autoencoder_module(cfg).apply({"params": ae_params}, upper, method=MotionAutoencoder.encode)


def decode(ae_params: Params, z: jax.Array, *, cfg: TGSTConfig) -> tuple[jax.Array, jax.Array]:
    """Latents ``(batch, T, 16)`` -> (upper ``(batch, 4T, 39)``, lower ``(batch, 4T, 24)``)."""
    m = autoencoder_module(cfg)
    upper = m.apply({"params": ae_params}, z, method=MotionAutoencoder.decode_upper)
    lower = m.apply({"params": ae_params}, z, method=MotionAutoencoder.decode_lower)
    return upper, lower


def transformer_encode(tr_params: Params, tokens: jax.Array, *, cfg: TGSTConfig):
    """T_E: tokens ``(batch, N, d)`` -> (encoded ``(batch, 1 + N, d)``, aux with keys / cls)."""
    return transformer_module(cfg).apply({"params": tr_params}, tokens, method=StyleTransformer.encode)


def transformer_decode(tr_params: Params, encoded_content: jax.Array, encoded_style: jax.Array, *,
                       cfg: TGSTConfig):
    """T_D: (encoded content, encoded style) -> (decoded content ``(batch, Nc, d)``, aux), eq. 3."""
    return transformer_module(cfg).apply({"params": tr_params}, encoded_content, encoded_style,
                                         method=StyleTransformer.decode)


def swap_encoded(tr_params: Params, encoded_content: jax.Array, encoded_style: jax.Array,
                 style_tokens: jax.Array, *, cfg: TGSTConfig, hard: bool = False):
    """Decode and swap: eq. 3 then eq. 4 (or eq. 19 when ``hard``); returns (tokens, swap weights)."""
    decoded, _ = transformer_decode(tr_params, encoded_content, encoded_style, cfg=cfg)
    if hard:
        weights = swap.hard_swap_weights(decoded, encoded_style)
    else:
        weights = swap.soft_swap_weights(decoded, encoded_style, cfg.swap_temperature)
    return swap.apply_swap(weights, style_tokens), weights


def transfer_tokens(tr_params: Params, content_tokens: jax.Array, style_tokens: jax.Array, *, cfg: TGSTConfig,
                    hard: bool = False):
    """g^{s|c} from raw tokens ``(batch, Nc, d)``, ``(batch, Ns, d)`` -> (tokens ``(batch, Nc, d)``, aux)."""
    enc_c, aux_c = transformer_encode(tr_params, content_tokens, cfg=cfg)
    enc_s, aux_s = transformer_encode(tr_params, style_tokens, cfg=cfg)
    tokens, weights = swap_encoded(tr_params, enc_c, enc_s, style_tokens, cfg=cfg, hard=hard)
    return tokens, {"swap_weights": weights, "content_cls": aux_c["cls"], "style_cls": aux_s["cls"]}


def transformer_loss_terms(tr_params: Params, content_tokens: jax.Array, style_tokens: jax.Array, *,
                           cfg: TGSTConfig) -> dict[str, jax.Array]:
    """Per-example loss terms ``(batch,)`` of eqs. 5-11 and their weighted sum (eq. 12) under ``"loss"``.

    Switched-off terms are not computed and reported as zeros.
    References: Kuriyama et al. 2022, eqs. 5-12.
    """
    enc_c, aux_c = transformer_encode(tr_params, content_tokens, cfg=cfg)
    enc_s, aux_s = transformer_encode(tr_params, style_tokens, cfg=cfg)
    transferred, _ = swap_encoded(tr_params, enc_c, enc_s, style_tokens, cfg=cfg)  # g^{s|c}, eq. 4
    zeros = jnp.zeros(content_tokens.shape[:1], content_tokens.dtype)
    terms = {"identity": zeros, "cyclic": zeros, "structure": zeros, "appearance": zeros}
    if cfg.use_identity:  # eq. 5: each clip transferred with itself as style
        c_id, _ = swap_encoded(tr_params, enc_c, enc_c, content_tokens, cfg=cfg)
        s_id, _ = swap_encoded(tr_params, enc_s, enc_s, style_tokens, cfg=cfg)
        terms["identity"] = losses.identity_loss(c_id, content_tokens, s_id, style_tokens)
    if cfg.use_cyclic or cfg.use_structure or cfg.use_appearance:
        enc_x, aux_x = transformer_encode(tr_params, transferred, cfg=cfg)
        if cfg.use_cyclic:  # eqs. 6-8: back-transfer with the content as style
            cyc, _ = swap_encoded(tr_params, enc_x, enc_c, content_tokens, cfg=cfg)
            terms["cyclic"] = losses.cyclic_loss(cyc, content_tokens)
        if cfg.use_structure:  # eqs. 9-10
            terms["structure"] = losses.structure_loss(aux_c["keys"], aux_x["keys"])
        if cfg.use_appearance:  # eq. 11
            terms["appearance"] = losses.appearance_loss(aux_s["cls"], aux_x["cls"])
    terms["loss"] = losses.total_transformer_loss(
        terms["identity"], terms["cyclic"], terms["structure"], terms["appearance"],
        lambda_identity=cfg.lambda_identity, lambda_cyclic=cfg.lambda_cyclic,
        lambda_structure=cfg.lambda_structure, lambda_appearance=cfg.lambda_appearance,
        use_identity=cfg.use_identity, use_cyclic=cfg.use_cyclic, use_structure=cfg.use_structure,
        use_appearance=cfg.use_appearance)
    return terms


def transfer_latents(tr_params: Params, content_z: jax.Array, style_z: jax.Array, *, cfg: TGSTConfig,
                     method: str = "soft", content_valid: int | None = None, style_valid: int | None = None):
    """Transfer latents ``(batch, Tc, 16)`` to the style of ``(batch, Ts, 16)``: (``(batch, Tc, 16)``, aux).

    method: ``"soft"`` (eq. 4), ``"hard"`` (eq. 19), ``"adain"`` (eq. 17) or ``"avatarnet"`` (eq. 18).
    ``*_valid``: latent frames of the real clips (statistics of the baselines ignore the padding).
    """
    w, h = cfg.token_width, cfg.token_stride
    if method in ("soft", "hard"):
        c_tok, s_tok = tokenize(content_z, w, h), tokenize(style_z, w, h)
        tokens, aux = transfer_tokens(tr_params, c_tok, s_tok, cfg=cfg, hard=(method == "hard"))
        return detokenize(tokens, content_z.shape[1], w, h), aux
    if method == "adain":
        z = baselines.adain_latents(content_z, style_z, content_valid=content_valid, style_valid=style_valid)
        return z, {}
    if method == "avatarnet":
        return baselines.avatarnet_swap(content_z, style_z, w=w, h=h, content_valid=content_valid,
                                        style_valid=style_valid), {}
    raise ValueError(f"unknown transfer method {method!r} (expected one of {METHODS})")


def transfer_arrays(params: Params, content_upper: jax.Array, style_upper: jax.Array, *, cfg: TGSTConfig,
                    method: str = "soft"):
    """Full transfer on arrays: content ``(batch, Fc, 39)`` in the style of ``(batch | 1, Fs, 39)``.

    Returns (upper ``(batch, Fc, 39)``, lower ``(batch, Fc, 24)``, aux). Pads both clips to a multiple of
    16 frames (edge frames), encodes them, tokenizes, transfers (``method``), cross-fades the tokens back,
    decodes both body halves and trims to Fc. Clips shorter than 16 frames raise ``ClipTooShortError``.
    Jit with ``static_argnames=("cfg", "method")``.
    References: Kuriyama et al. 2022, Fig. 2.
    """
    chex.assert_rank([content_upper, style_upper], 3)
    b, fc, _ = content_upper.shape
    fs = style_upper.shape[1]
    if style_upper.shape[0] == 1 and b != 1:
        style_upper = jnp.broadcast_to(style_upper, (b,) + style_upper.shape[1:])
    chex.assert_axis_dimension(style_upper, 0, b)
    m, red = cfg.frame_multiple, cfg.autoencoder.time_reduction
    zc = encode(params["autoencoder"], pad_frames(content_upper, m, min_frames=cfg.min_frames), cfg=cfg)
    zs = encode(params["autoencoder"], pad_frames(style_upper, m, min_frames=cfg.min_frames), cfg=cfg)
    zx, aux = transfer_latents(params["transformer"], zc, zs, cfg=cfg, method=method,
                               content_valid=math.ceil(fc / red), style_valid=math.ceil(fs / red))
    upper, lower = decode(params["autoencoder"], zx, cfg=cfg)
    aux = dict(aux, content_latents=zc, style_latents=zs, transferred_latents=zx)
    upper, lower = trim_frames(upper, fc), trim_frames(lower, fc)
    chex.assert_shape(upper, (b, fc, cfg.autoencoder.upper_channels))
    chex.assert_shape(lower, (b, fc, cfg.autoencoder.lower_channels))
    return upper, lower, aux

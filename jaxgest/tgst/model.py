"""TGST as pure functions of parameter pytrees: modules, init, encode/decode, token transfer.

``params = {"autoencoder": <MotionAutoencoder params>, "transformer": <StyleTransformer params>}`` (plain
Flax ``params`` collections). Every function takes ``cfg`` (a hashable
:class:`~jaxgest.tgst.config.ModelConfig`) as a keyword so it can be a jit static argument:
``jax.jit(transfer_arrays, static_argnames=("cfg", "method"))``.

The training losses built from these functions are in :mod:`jaxgest.tgst.losses`.
References: Kuriyama et al. 2022, §3 (Fig. 2 data flow), §4.3 (baselines).
"""

from __future__ import annotations

import math
from typing import Any

import chex
import jax
import jax.numpy as jnp

from jaxgest.tgst import baselines, swap
from jaxgest.tgst.autoencoder import MotionAutoencoder
from jaxgest.tgst.config import ModelConfig
from jaxgest.tgst.tokens import check_clip_length, detokenize, num_tokens, padded_length, tokenize
from jaxgest.tgst.transformer import StyleTransformer

#: the four methods compared in the paper (§4.3, Tables 2-3)
TRANSFER_METHODS = ("soft", "hard", "adain", "avatarnet")
#: every ``method=`` accepted: the four, ``"coherent"`` (the tokens along one constant-rate path through the
#: style, chosen by eq. 4's similarities; not in the paper, swap.coherent_swap_weights) and ``"autoencoder"``,
#: the content's plain autoencoder round trip (no style; a diagnostic and control)
METHODS = TRANSFER_METHODS + ("coherent", "autoencoder")
#: what ``jaxgest tgst evaluate`` reports by default: the paper's four and the coherent swap beside them
EVALUATE_METHODS = TRANSFER_METHODS + ("coherent",)
Params = dict[str, Any]


def autoencoder_module(cfg: ModelConfig) -> MotionAutoencoder:
    return MotionAutoencoder(cfg.autoencoder)


def transformer_module(cfg: ModelConfig) -> StyleTransformer:
    return StyleTransformer(cfg.transformer)


def init_params(cfg: ModelConfig, key: jax.Array) -> Params:
    """Fresh parameters ``{"autoencoder": ..., "transformer": ...}`` for ``cfg``."""
    k_ae, k_tr = jax.random.split(key)
    frames = cfg.frame_multiple
    ae = autoencoder_module(cfg).init(k_ae, jnp.zeros((1, frames, cfg.autoencoder.upper_channels)))
    tokens = jnp.zeros((1, 3, cfg.transformer.token_dim))
    tr = transformer_module(cfg).init(k_tr, tokens, tokens)
    return {"autoencoder": ae["params"], "transformer": tr["params"]}


def encode(ae_params: Params, upper: jax.Array, *, cfg: ModelConfig) -> jax.Array:
    """Upper-body exp-maps ``(batch, F, 39)`` -> latents ``(batch, ceil(F / 4), 16)``."""
    return autoencoder_module(cfg).apply({"params": ae_params}, upper, method=MotionAutoencoder.encode)


def decode(ae_params: Params, z: jax.Array, *, cfg: ModelConfig) -> tuple[jax.Array, jax.Array]:
    """Latents ``(batch, T, 16)`` -> (upper ``(batch, 4T, 39)``, lower ``(batch, 4T, 24)``)."""
    m = autoencoder_module(cfg)
    upper = m.apply({"params": ae_params}, z, method=MotionAutoencoder.decode_upper)
    lower = m.apply({"params": ae_params}, z, method=MotionAutoencoder.decode_lower)
    return upper, lower


def edge_layout(frames: int, *, cfg: ModelConfig) -> tuple[int, int]:
    """(lead, total) frames of a clip of ``frames`` frames after :func:`pad_clip`.

    lead = ``cfg.edge_frames`` replicated first frames; the end is replicated by at least as many frames and
    up to a multiple of ``cfg.frame_multiple`` in total.
    """
    lead = cfg.edge_frames
    return lead, padded_length(frames + 2 * lead, cfg.frame_multiple)


def pad_clip(x: jax.Array, *, cfg: ModelConfig) -> jax.Array:
    """Clip ends (docs/design.md §3): replicate-pad ``(batch, F, ch)`` at both ends (see :func:`edge_layout`).

    The one place where every encode path (autoencoder training windows, transformer training, transfers,
    round trips, diagnostics) pads a clip, so the encoder's zero padding only ever meets copies of the edge
    frames, never real frames. Raises :class:`ClipTooShortError` when ``F < cfg.min_frames``. With
    ``cfg.edge_frames == 0`` it is the end-only padding of :func:`jaxgest.tgst.tokens.pad_frames`.
    """
    chex.assert_rank(x, 3)
    f = x.shape[1]
    check_clip_length(f, min_frames=cfg.min_frames)
    lead, total = edge_layout(f, cfg=cfg)
    if total == f:
        return x
    return jnp.pad(x, ((0, 0), (lead, total - f - lead), (0, 0)), mode="edge")


def trim_clip(y: jax.Array, frames: int, *, cfg: ModelConfig) -> jax.Array:
    """Inverse of :func:`pad_clip` on decoded frames: the ``frames`` frames after the lead."""
    return y[:, cfg.edge_frames:cfg.edge_frames + frames]


def clip_latent_range(frames: int, *, cfg: ModelConfig) -> tuple[int, int]:
    """[start, stop) of the latent frames of :func:`encode_clip` that belong to the real clip."""
    red = cfg.autoencoder.time_reduction
    start = cfg.edge_frames // red
    return start, start + math.ceil(frames / red)


def encode_clip(ae_params: Params, upper: jax.Array, *, cfg: ModelConfig) -> jax.Array:
    """Upper-body exp-maps ``(batch, F, 39)`` -> latents of the padded clip (:func:`pad_clip`).

    Decode them with :func:`decode` and cut the result with :func:`trim_clip`; the latents of the real
    frames are :func:`clip_latent_range`.
    """
    return encode(ae_params, pad_clip(upper, cfg=cfg), cfg=cfg)


def reconstruct(ae_params: Params, upper: jax.Array, *, cfg: ModelConfig) -> tuple[jax.Array, jax.Array]:
    """The autoencoder round trip ``(batch, F, 39)`` -> (upper ``(batch, F, 39)``, lower ``(batch, F, 24)``)."""
    f = upper.shape[1]
    up, lo = decode(ae_params, encode_clip(ae_params, upper, cfg=cfg), cfg=cfg)
    return trim_clip(up, f, cfg=cfg), trim_clip(lo, f, cfg=cfg)


def transformer_encode(tr_params: Params, tokens: jax.Array, *, cfg: ModelConfig, valid=None):
    """T_E: tokens ``(batch, N, d)`` -> (encoded ``(batch, 1 + N, d)``, aux with keys / cls).

    valid: optional ``(batch, N)`` bool of the real tokens of a padded set (padded ones are not attended to).
    """
    return transformer_module(cfg).apply({"params": tr_params}, tokens, valid, method=StyleTransformer.encode)


def transformer_decode(tr_params: Params, encoded_content: jax.Array, encoded_style: jax.Array, *,
                       cfg: ModelConfig, style_valid=None):
    """T_D: (encoded content, encoded style) -> (decoded content ``(batch, Nc, d)``, aux), eq. 3."""
    return transformer_module(cfg).apply({"params": tr_params}, encoded_content, encoded_style, style_valid,
                                         method=StyleTransformer.decode)


def swap_encoded(tr_params: Params, encoded_content: jax.Array, encoded_style: jax.Array,
                 style_tokens: jax.Array, *, cfg: ModelConfig, hard: bool = False, style_valid=None,
                 coherent: bool = False, content_valid=None):
    """Decode and swap: eq. 3 then eq. 4 (or eq. 19 when ``hard``; the constant-rate path of
    :func:`jaxgest.tgst.swap.coherent_swap_weights` when ``coherent``); returns (tokens, swap weights).

    style_valid: optional ``(batch, Ns)`` bool of the real style tokens of a padded style set (training on
    whole style clips, :func:`jaxgest.tgst.data.transformer_batch`): padded tokens get weight 0.
    content_valid: optional ``(batch, Nc)`` bool of the real content tokens (only the coherent path reads it:
    it scores the real content tokens only).
    """
    decoded, _ = transformer_decode(tr_params, encoded_content, encoded_style, cfg=cfg, style_valid=style_valid)
    if coherent:
        weights = swap.coherent_swap_weights(decoded, encoded_style, cfg.swap_temperature,
                                             similarity=cfg.swap_similarity, style_valid=style_valid,
                                             content_valid=content_valid)
    elif hard:
        weights = swap.hard_swap_weights(decoded, encoded_style, similarity=cfg.swap_similarity,
                                         style_valid=style_valid)
    else:
        weights = swap.soft_swap_weights(decoded, encoded_style, cfg.swap_temperature,
                                         similarity=cfg.swap_similarity, style_valid=style_valid)
    return swap.apply_swap(weights, style_tokens), weights


def transfer_tokens(tr_params: Params, content_tokens: jax.Array, style_tokens: jax.Array, *, cfg: ModelConfig,
                    hard: bool = False, coherent: bool = False, content_valid=None, style_valid=None):
    """g^{s|c} from raw tokens ``(batch, Nc, d)``, ``(batch, Ns, d)`` -> (tokens ``(batch, Nc, d)``, aux).

    ``content_valid`` / ``style_valid``: optional ``(batch, Nc)`` / ``(batch, Ns)`` bools of the real tokens of
    padded sets (real tokens first): padded tokens are never attended to and get swap weight exactly 0, so the
    real tokens' result is the one of the unpadded sets.
    """
    enc_c, aux_c = transformer_encode(tr_params, content_tokens, cfg=cfg, valid=content_valid)
    enc_s, aux_s = transformer_encode(tr_params, style_tokens, cfg=cfg, valid=style_valid)
    tokens, weights = swap_encoded(tr_params, enc_c, enc_s, style_tokens, cfg=cfg, hard=hard,
                                   coherent=coherent, style_valid=style_valid, content_valid=content_valid)
    return tokens, {"swap_weights": weights, "content_cls": aux_c["cls"], "style_cls": aux_s["cls"]}


def transfer_latents(tr_params: Params, content_z: jax.Array, style_z: jax.Array, *, cfg: ModelConfig,
                     method: str = "soft", content_valid=None, style_valid=None, content_tokens_valid=None,
                     style_tokens_valid=None):
    """Transfer latents ``(batch, Tc, 16)`` to the style of ``(batch, Ts, 16)``: (``(batch, Tc, 16)``, aux).

    method: ``"soft"`` (eq. 4), ``"hard"`` (eq. 19), ``"adain"`` (eq. 17), ``"avatarnet"`` (eq. 18),
    ``"coherent"`` (not in the paper; :func:`swap_encoded`) or ``"autoencoder"`` (the content latents
    unchanged). ``*_valid``: the latent frames of the real clips, an int (the first frames) or a
    ``(start, stop)`` range (static or traced); the baselines' statistics ignore the padding.
    ``*_tokens_valid``: optional ``(batch, N)`` bools of the real tokens of clips padded to a length bucket
    (:func:`transfer_tokens`; Avatar-net never picks a padded style token).
    """
    w, h = cfg.token_width, cfg.token_stride
    if method in ("soft", "hard", "coherent"):
        c_tok, s_tok = tokenize(content_z, w, h), tokenize(style_z, w, h)
        tokens, aux = transfer_tokens(tr_params, c_tok, s_tok, cfg=cfg, hard=(method == "hard"),
                                      coherent=(method == "coherent"), content_valid=content_tokens_valid,
                                      style_valid=style_tokens_valid)
        return detokenize(tokens, content_z.shape[1], w, h), aux
    if method == "adain":
        z = baselines.adain_latents(content_z, style_z, content_valid=content_valid, style_valid=style_valid)
        return z, {}
    if method == "avatarnet":
        return baselines.avatarnet_swap(content_z, style_z, w=w, h=h, content_valid=content_valid,
                                        style_valid=style_valid, style_token_valid=style_tokens_valid), {}
    if method == "autoencoder":
        return content_z, {}
    raise ValueError(f"unknown transfer method {method!r} (expected one of {METHODS})")


def encode_pair(ae_params: Params, content_upper: jax.Array, style_upper: jax.Array, *, cfg: ModelConfig):
    """Padded content latents, the style latents that the swap sees, and the real latent ranges of both.

    The content keeps its padded latents (the decoder needs them as context at the clip ends; the output is
    trimmed); the style is cut to its real frames (edge copies would add frozen style tokens). With
    ``cfg.edge_frames == 0`` (old runs) both keep their end padding, as before.
    """
    fc, fs = content_upper.shape[1], style_upper.shape[1]
    zc = encode_clip(ae_params, content_upper, cfg=cfg)
    zs = encode_clip(ae_params, style_upper, cfg=cfg)
    c_range, s_range = clip_latent_range(fc, cfg=cfg), clip_latent_range(fs, cfg=cfg)
    if cfg.edge_frames:
        zs = zs[:, s_range[0]:s_range[1]]
        s_range = (0, zs.shape[1])
        check_clip_length(zs.shape[1], min_frames=cfg.token_width, what="style latent clip")
    return zc, zs, c_range, s_range


def _broadcast_style(content_upper, style_upper):
    chex.assert_rank([content_upper, style_upper], 3)
    b = content_upper.shape[0]
    if style_upper.shape[0] == 1 and b != 1:
        style_upper = jnp.broadcast_to(style_upper, (b,) + style_upper.shape[1:])
    chex.assert_axis_dimension(style_upper, 0, b)
    return style_upper


def _ceil_div(a, b):
    """ceil(a / b) of non-negative ints or int arrays (traceable)."""
    return -((-a) // b)


def exact_latent_count(frames, *, cfg: ModelConfig, role: str):
    """Latent frames the transfer of a clip of exactly ``frames`` frames tokenizes (int or traced int array).

    ``role="content"``: the whole padded clip (:func:`edge_layout`); ``"style"``: with ``cfg.edge_frames`` the
    real frames only (:func:`encode_pair`), else the clip padded at the end to ``cfg.frame_multiple`` frames.
    """
    red = cfg.autoencoder.time_reduction
    if role == "style" and cfg.edge_frames:
        return _ceil_div(frames, red)
    return _ceil_div(frames + 2 * cfg.edge_frames, cfg.frame_multiple) * cfg.frame_multiple // red


def exact_token_count(frames, *, cfg: ModelConfig, role: str):
    """Gesture tokens (eq. 1) of the transfer of a clip of exactly ``frames`` frames: the content tokens
    (``role="content"``) or the swap pool (``"style"``); :func:`jaxgest.tgst.tokens.num_tokens` of
    :func:`exact_latent_count`."""
    return _ceil_div(exact_latent_count(frames, cfg=cfg, role=role), cfg.token_stride) - 1


def _real_frames(frames, batch: int):
    return jnp.broadcast_to(jnp.reshape(jnp.asarray(frames, jnp.int32), (-1,)), (batch,))


def mask_padding(zc, zs, c_range, s_range, content_frames, style_frames, *, cfg: ModelConfig):
    """The latents and validity of a pair padded at the end to a length bucket, as the exact-length pair.

    ``content_frames`` / ``style_frames``: the real frames of each clip (ints or traced ``()`` / ``(batch,)``
    int arrays, so one compilation serves every length of a bucket), or None (the clip is not padded).
    Returns ``(zs, c_range, s_range, content_tokens_valid, style_tokens_valid)``: the style latents past the
    real ones replaced by copies of the last real one (as :func:`jaxgest.tgst.tokens.tokenize` pads the
    exact-length clip), the real latent ranges for the baselines' statistics, and ``(batch, N)`` bools of the
    tokens the exact-length transfer has (None where not padded). With these the swap pool holds exactly
    the exact-length style tokens: padded tokens are never attended to and get swap weight 0.
    """
    b = zc.shape[0]
    red, w, h = cfg.autoencoder.time_reduction, cfg.token_width, cfg.token_stride
    c_tokens_valid = s_tokens_valid = None
    if content_frames is not None:
        fc = _real_frames(content_frames, b)
        nc = num_tokens(zc.shape[1], w=w, h=h)
        c_tokens_valid = jnp.arange(nc)[None, :] < exact_token_count(fc, cfg=cfg, role="content")[:, None]
        c_range = (c_range[0], c_range[0] + _ceil_div(fc, red))
    if style_frames is not None:
        fs = _real_frames(style_frames, b)
        keep = exact_latent_count(fs, cfg=cfg, role="style")
        idx = jnp.minimum(jnp.arange(zs.shape[1])[None, :], keep[:, None] - 1)
        zs = jnp.take_along_axis(zs, idx[..., None], axis=1)
        ns = num_tokens(zs.shape[1], w=w, h=h)
        s_tokens_valid = jnp.arange(ns)[None, :] < exact_token_count(fs, cfg=cfg, role="style")[:, None]
        s_range = (s_range[0], s_range[0] + _ceil_div(fs, red))
    return zs, c_range, s_range, c_tokens_valid, s_tokens_valid


def transfer_arrays(params: Params, content_upper: jax.Array, style_upper: jax.Array, *, cfg: ModelConfig,
                    method: str = "soft", content_frames=None, style_frames=None):
    """Full transfer on arrays: content ``(batch, Fc, 39)`` in the style of ``(batch | 1, Fs, 39)``.

    Returns (upper ``(batch, Fc, 39)``, lower ``(batch, Fc, 24)``, aux). Pads both clips at both ends with
    copies of their edge frames (:func:`pad_clip`), encodes them, tokenizes, transfers (``method``),
    cross-fades the tokens back, decodes both body halves and trims to Fc (:func:`trim_clip`).
    ``method="autoencoder"`` returns the content's plain round trip (the style is ignored).
    ``content_frames`` / ``style_frames`` (optional, traced ints): the clips were padded at the end to a length
    bucket and only their first frames are real; the padded tokens are masked (:func:`mask_padding`: no
    attention, swap weight 0, not in the baselines' statistics), so the real frames' result is the
    exact-length one (pad with the last frame, ``numpy.pad(mode="edge")``, and it is equal to float error).
    Clips shorter than 16 frames raise ``ClipTooShortError``.
    Jit with ``static_argnames=("cfg", "method")``.
    References: Kuriyama et al. 2022, Fig. 2.
    """
    style_upper = _broadcast_style(content_upper, style_upper)
    b, fc, _ = content_upper.shape
    zc, zs, c_range, s_range = encode_pair(params["autoencoder"], content_upper, style_upper, cfg=cfg)
    zs, c_range, s_range, c_tok, s_tok = mask_padding(zc, zs, c_range, s_range, content_frames, style_frames,
                                                      cfg=cfg)
    zx, aux = transfer_latents(params["transformer"], zc, zs, cfg=cfg, method=method,
                               content_valid=c_range, style_valid=s_range, content_tokens_valid=c_tok,
                               style_tokens_valid=s_tok)
    upper, lower = decode(params["autoencoder"], zx, cfg=cfg)
    aux = dict(aux, content_latents=zc, style_latents=zs, transferred_latents=zx)
    if s_tok is not None:
        aux["style_tokens_valid"] = s_tok
    upper, lower = trim_clip(upper, fc, cfg=cfg), trim_clip(lower, fc, cfg=cfg)
    chex.assert_shape(upper, (b, fc, cfg.autoencoder.upper_channels))
    chex.assert_shape(lower, (b, fc, cfg.autoencoder.lower_channels))
    return upper, lower, aux


def swap_weights(params: Params, content_upper: jax.Array, style_upper: jax.Array, *,
                 cfg: ModelConfig, content_frames=None, style_frames=None) -> jax.Array:
    """Soft-swap weights (eq. 4) of a transfer, ``(batch, Nc, Ns)``, rows on the simplex.

    Row n is content token n of the real clip (token 0 starts at the content's first frame; tokens that
    cover only edge padding are left out), column m is style token m (token 0 starts at the style's first
    frame), so "argmax within +-1 of the query's own index" compares like positions. Same inputs as
    :func:`transfer_arrays` (``*_frames``: clips padded to a length bucket; the padded style tokens' columns
    are then exactly 0); jit with ``static_argnames="cfg"``.
    References: Kuriyama et al. 2022, eq. 4.
    """
    style_upper = _broadcast_style(content_upper, style_upper)
    zc, zs, c_range, s_range = encode_pair(params["autoencoder"], content_upper, style_upper, cfg=cfg)
    first_latent = c_range[0]
    zs, _, _, c_tok, s_tok = mask_padding(zc, zs, c_range, s_range, content_frames, style_frames, cfg=cfg)
    w, h = cfg.token_width, cfg.token_stride
    _, aux = transfer_tokens(params["transformer"], tokenize(zc, w, h), tokenize(zs, w, h), cfg=cfg,
                             content_valid=c_tok, style_valid=s_tok)
    first = first_latent // h
    return aux["swap_weights"][:, first:first + num_tokens(c_range[1] - c_range[0], w=w, h=h)]

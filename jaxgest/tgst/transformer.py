"""Style transformer: banded self-attention encoder T_E with a CLS token, cross-attention decoder T_D.

Sequences carry the CLS token at index 0 followed by N gesture tokens ("combined index"). Both modules
are one block with a single head of width d_g = 64 (q/k/v/out 64x64, MLP 64 -> GELU -> 64).

``variant="paper"`` (default, the paper's text): pre-LN ("layer normalization as a preprocessing step",
§3.4), sinusoidal positions over the combined index (CLS at position 0), band |i - j| <= omega between
gesture tokens while CLS attends to and is attended by every token. ``token_positions="none"`` leaves the
positions out: the tokens then carry no index, as in the authors' code (whose table is added along the
batch axis), and the soft swap cannot match content and style tokens by their index.

``variant="authors"`` (the public PyTorch code, for comparison): LN(x + pe) -> attention ->
LN(z + attention) -> + MLP (one LN shared by both residuals, or two with ``layernorms_per_block=2``); the
band on the combined index is i - omega <= j < i + omega for every gesture row i >= 1 (so a gesture token
sees CLS only when i <= omega) and the CLS row is dense; the positional table (150 entries, angle 2*pi*pos*f)
is added along the *batch* axis (``pe[b]`` is added to every token of batch element b -- a bug of the
code, reproduced here; batches larger than 150 are an error, as they are there).

The decoder (both variants) drops the CLS rows of its inputs and normalises content and style with its
(first) LayerNorm before the projections, as the authors' code does.

The band is computed blockwise by default: gesture queries are cut into blocks of ``block_size >= omega``
tokens and each block attends to the CLS key plus the keys of its own and both neighbouring blocks, so
memory and time are O(N * block_size) and no N x N matrix exists (sequences of at most ``SHORT_BLOCKS``
blocks, where one window spans them, take the dense form); ``attention_impl="dense"`` is the masked
reference (it also returns the attention weights in ``aux``).

References: Kuriyama et al. 2022, §3.4, eqs. 2-3; Dosovitskiy et al. 2021 (ViT); Vaswani et al. 2017.
"""

from __future__ import annotations

import math

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.nn import gelu_exact
from jaxgest.nn import sinusoidal_positions  # noqa: F401  (eq. 2; re-exported)
from jaxgest.tgst.config import TransformerConfig

_MASKED = -1e9  # finite, so rows with every key masked (padding) stay NaN-free
#: blockwise attention takes the dense masked form for sequences of at most this many blocks: a query block
#: sees 3 blocks of keys, so up to 3 blocks the dense (1 + N)^2 scores are no more work than the blockwise
#: N * (1 + 3 * block) and far fewer operations (a training window of 288 frames is 36 tokens: the fit-motion
#: transformer step 10-12 % faster on 2 CPU cores, same values to float rounding)
SHORT_BLOCKS = 3


def band_valid(query_index: np.ndarray, key_index: np.ndarray, *, omega: int, variant: str) -> np.ndarray:
    """Whether combined-index query i may attend to key j (CLS = 0, gesture tokens 1..N); broadcasts.

    paper: CLS row and CLS column always; otherwise |i - j| <= omega (§3.4, "masking ... k < i - omega or
    k > i + omega"). authors: CLS row always; otherwise i - omega <= j < i + omega.
    """
    qi, kj = np.asarray(query_index), np.asarray(key_index)
    if variant == "paper":
        return (qi == 0) | (kj == 0) | (np.abs(qi - kj) <= omega)
    if variant == "authors":
        return (qi == 0) | ((kj >= qi - omega) & (kj < qi + omega))
    raise ValueError(f"unknown variant {variant!r}")


def band_mask(num_tokens: int, *, omega: int, variant: str = "paper") -> np.ndarray:
    """Dense boolean mask ``(1 + N, 1 + N)`` of the encoder self-attention (row = query, CLS first)."""
    idx = np.arange(num_tokens + 1)
    return band_valid(idx[:, None], idx[None, :], omega=omega, variant=variant)


def _key_valid(valid, batch: int, n: int):
    """Keys ``(batch, 1 + N)`` that may be attended to: CLS always, gesture token j where ``valid[:, j]``
    (``None``: every token)."""
    if valid is None:
        return None
    chex.assert_shape(valid, (batch, n))
    return jnp.concatenate([jnp.ones((batch, 1), bool), valid.astype(bool)], axis=1)


def dense_banded_attention(q, k, v, *, omega: int, variant: str = "paper", valid=None):
    """Reference masked attention; q, k, v ``(batch, 1 + N, d)`` -> (out ``(batch, 1 + N, d)``, weights).

    valid: optional ``(batch, N)`` bool, the real gesture tokens of a padded sequence: padded tokens are
    never attended to (their own rows are computed but meaningless).
    """
    chex.assert_equal_shape([q, k, v])
    d = q.shape[-1]
    mask = jnp.asarray(band_mask(q.shape[1] - 1, omega=omega, variant=variant))[None]
    kv = _key_valid(valid, q.shape[0], q.shape[1] - 1)
    if kv is not None:
        mask = mask & kv[:, None, :]
    scores = jnp.einsum("bqd,bkd->bqk", q, k) / math.sqrt(d)
    weights = jax.nn.softmax(jnp.where(mask, scores, _MASKED), axis=-1)
    return jnp.einsum("bqk,bkd->bqd", weights, v), weights


def blockwise_banded_attention(q, k, v, *, omega: int, variant: str = "paper", block_size: int = 32,
                               valid=None):
    """Banded attention in O(N * block_size): equal to :func:`dense_banded_attention` (up to float error).

    q, k, v: ``(batch, 1 + N, d)`` with CLS at index 0. Gesture queries are grouped in blocks of
    ``block_size >= omega``; block b attends to the CLS key and to the gesture keys of blocks b-1, b, b+1
    (which contain its whole band), with the band mask applied inside. The CLS query attends densely.
    valid: optional ``(batch, N)`` bool of the real gesture tokens (padded keys are masked out).
    """
    chex.assert_equal_shape([q, k, v])
    if block_size < omega:
        raise ValueError(f"block_size ({block_size}) must be >= omega ({omega})")
    bsz, n1, d = q.shape
    n = n1 - 1
    nb = max(1, -(-n // block_size))
    size = nb * block_size
    scale = 1.0 / math.sqrt(d)
    cls_q, cls_k, cls_v = q[:, 0], k[:, 0], v[:, 0]

    def pad_blocks(x, before, after):
        x = jnp.pad(x[:, 1:], ((0, 0), (before, size - n + after), (0, 0)))
        return x.reshape(bsz, -1, block_size, d)

    qb = pad_blocks(q, 0, 0)  # (b, nb, B, d)
    kb, vb = pad_blocks(k, block_size, block_size), pad_blocks(v, block_size, block_size)  # (b, nb + 2, B, d)
    kw = jnp.concatenate([kb[:, :-2], kb[:, 1:-1], kb[:, 2:]], axis=2)  # (b, nb, 3B, d)
    vw = jnp.concatenate([vb[:, :-2], vb[:, 1:-1], vb[:, 2:]], axis=2)

    # Static masks from combined indices: query 1 + i, window key 1 + j, j = (blk - 1) * B + c.
    blk = np.arange(nb)[:, None, None]
    qi = 1 + blk * block_size + np.arange(block_size)[None, :, None]  # (nb, B, 1)
    j = (blk - 1) * block_size + np.arange(3 * block_size)[None, None, :]  # (nb, 1, 3B)
    win_valid = band_valid(qi, 1 + j, omega=omega, variant=variant) & (j >= 0) & (j < n)  # (nb, B, 3B)
    cls_valid = band_valid(qi[..., 0], 0, omega=omega, variant=variant)  # (nb, B)

    s_win = jnp.einsum("bnqd,bnkd->bnqk", qb, kw) * scale
    s_cls = jnp.einsum("bnqd,bd->bnq", qb, cls_k) * scale
    s = jnp.concatenate([s_cls[..., None], s_win], axis=-1)
    allowed = jnp.asarray(np.concatenate([cls_valid[..., None], win_valid], axis=-1))[None]  # (1, nb, B, 1+3B)
    kv = _key_valid(valid, bsz, n)
    if kv is not None:  # the padded keys of each window, (b, nb, 1 + 3B)
        vk = jnp.pad(kv[:, 1:], ((0, 0), (block_size, size - n + block_size))).reshape(bsz, -1, block_size)
        vk = jnp.concatenate([vk[:, :-2], vk[:, 1:-1], vk[:, 2:]], axis=2)
        vk = jnp.concatenate([jnp.ones((bsz, nb, 1), bool), vk], axis=-1)
        allowed = allowed & vk[:, :, None, :]
    w = jax.nn.softmax(jnp.where(allowed, s, _MASKED), axis=-1)
    out = w[..., :1] * cls_v[:, None, None, :] + jnp.einsum("bnqk,bnkd->bnqd", w[..., 1:], vw)
    out = out.reshape(bsz, size, d)[:, :n]

    s0 = jnp.einsum("bd,bkd->bk", cls_q, k) * scale
    w0 = jax.nn.softmax(s0 if kv is None else jnp.where(kv, s0, _MASKED), axis=-1)  # CLS row: every key
    out0 = jnp.einsum("bk,bkd->bd", w0, v)
    return jnp.concatenate([out0[:, None], out], axis=1)


class _MLP(nn.Module):
    """Two d x d layers with GELU between (no hidden expansion, §3.4)."""

    dim: int

    @nn.compact
    def __call__(self, x):
        return nn.Dense(self.dim, name="fc_1")(gelu_exact(nn.Dense(self.dim, name="fc_0")(x)))


def _layernorms(count: int):
    first = nn.LayerNorm(epsilon=1e-5, name="ln")
    return first, (first if count == 1 else nn.LayerNorm(epsilon=1e-5, name="ln_mlp"))


class StyleTransformerEncoder(nn.Module):
    """T_E: tokens ``(batch, N, d)`` -> (encoded ``(batch, 1 + N, d)`` with CLS first, aux).

    aux: ``keys`` ``(batch, N, d)`` (gesture keys k_i = m_k LN(g_i + p_i), for the structure loss, eq. 9),
    ``cls`` ``(batch, d)`` (the CLS output, for the appearance loss), and ``attention``
    ``(batch, 1 + N, 1 + N)`` with the dense implementation only. ``valid`` (optional ``(batch, N)`` bool):
    the real tokens of a sequence padded to a common length; padded tokens are never attended to, so the
    outputs of the real tokens and CLS do not depend on the padding.
    References: Kuriyama et al. 2022, §3.4, eq. 2.
    """

    config: TransformerConfig

    @nn.compact
    def __call__(self, tokens: jax.Array, valid=None):
        cfg = self.config
        d = cfg.token_dim
        chex.assert_rank(tokens, 3)
        chex.assert_axis_dimension(tokens, 2, d)
        bsz, n, _ = tokens.shape
        cls = self.param("cls", nn.initializers.normal(stddev=1.0), (d,))
        x = jnp.concatenate([jnp.broadcast_to(cls.astype(tokens.dtype), (bsz, 1, d)), tokens], axis=1)
        if cfg.variant == "paper":
            if cfg.token_positions == "index":
                x = x + jnp.asarray(sinusoidal_positions(n + 1, d))[None]
        else:
            if bsz > cfg.max_authors_pe:
                raise ValueError(f"authors' variant adds positions along the batch axis: batch {bsz} > "
                                 f"{cfg.max_authors_pe}")
            x = x + jnp.asarray(sinusoidal_positions(bsz, d, angle_scale=2 * math.pi))[:, None, :]
        ln_attn, ln_mlp = _layernorms(cfg.layernorms_per_block)
        q_proj, k_proj, v_proj = (nn.Dense(d, name=nm) for nm in ("query", "key", "value"))
        o_proj, mlp = nn.Dense(d, name="out"), _MLP(d, name="mlp")

        z = ln_attn(x)
        q, k, v = q_proj(z), k_proj(z), v_proj(z)
        aux = {"keys": k[:, 1:]}
        if cfg.attention_impl == "dense":
            a, weights = dense_banded_attention(q, k, v, omega=cfg.omega, variant=cfg.variant, valid=valid)
            aux["attention"] = weights
        elif n <= SHORT_BLOCKS * cfg.block_size:  # one window spans the whole sequence: dense is less work
            a, _ = dense_banded_attention(q, k, v, omega=cfg.omega, variant=cfg.variant, valid=valid)
        else:
            a = blockwise_banded_attention(q, k, v, omega=cfg.omega, variant=cfg.variant,
                                           block_size=cfg.block_size, valid=valid)
        if cfg.variant == "paper":  # pre-LN
            x = x + o_proj(a)
            y = x + mlp(ln_mlp(x))
        else:  # authors: the residual starts from the normalised input, LN after the attention residual
            x = ln_mlp(z + o_proj(a))
            y = x + mlp(x)
        aux["cls"] = y[:, 0]
        return y, aux


class StyleTransformerDecoder(nn.Module):
    """T_D: cross-attention of content queries over style keys/values (no mask), then the MLP residual.

    encoded_content ``(batch, 1 + Nc, d)``, encoded_style ``(batch, 1 + Ns, d)`` (encoder outputs, CLS
    rows dropped here) -> (decoded content ``(batch, Nc, d)``, aux with ``attention`` (batch, Nc, Ns)).
    ``style_valid`` (optional ``(batch, Ns)`` bool): the real style tokens; padded ones are not attended to.
    References: Kuriyama et al. 2022, §3.4, eq. 3.
    """

    config: TransformerConfig

    @nn.compact
    def __call__(self, encoded_content: jax.Array, encoded_style: jax.Array, style_valid=None):
        cfg = self.config
        d = cfg.token_dim
        chex.assert_rank([encoded_content, encoded_style], 3)
        chex.assert_axis_dimension(encoded_content, 2, d)
        chex.assert_axis_dimension(encoded_style, 2, d)
        c, s = encoded_content[:, 1:], encoded_style[:, 1:]
        ln_attn, ln_mlp = _layernorms(cfg.layernorms_per_block)
        q_proj, k_proj, v_proj = (nn.Dense(d, name=nm) for nm in ("query", "key", "value"))
        o_proj, mlp = nn.Dense(d, name="out"), _MLP(d, name="mlp")

        zc, zs = ln_attn(c), ln_attn(s)
        scores = jnp.einsum("bqd,bkd->bqk", q_proj(zc), k_proj(zs)) / math.sqrt(d)
        if style_valid is not None:
            chex.assert_shape(style_valid, s.shape[:2])
            scores = jnp.where(style_valid.astype(bool)[:, None, :], scores, _MASKED)
        weights = jax.nn.softmax(scores, axis=-1)
        a = o_proj(jnp.einsum("bqk,bkd->bqd", weights, v_proj(zs)))
        if cfg.variant == "paper":
            x = c + a
            y = x + mlp(ln_mlp(x))
        else:
            x = ln_mlp(zc + a)
            y = x + mlp(x)
        return y, {"attention": weights}


class StyleTransformer(nn.Module):
    """Encoder and decoder together; ``encode`` / ``decode`` are applied with ``method=``.

    ``__call__(content_tokens, style_tokens)`` (for ``init``) returns T_D(T_E(g_c), T_E(g_s)), eq. 3.
    """

    config: TransformerConfig

    def setup(self):
        self.encoder = StyleTransformerEncoder(self.config)
        self.decoder = StyleTransformerDecoder(self.config)

    def encode(self, tokens: jax.Array, valid=None):
        return self.encoder(tokens, valid)

    def decode(self, encoded_content: jax.Array, encoded_style: jax.Array, style_valid=None):
        return self.decoder(encoded_content, encoded_style, style_valid)

    def __call__(self, content_tokens: jax.Array, style_tokens: jax.Array):
        enc_c, _ = self.encode(content_tokens)
        enc_s, _ = self.encode(style_tokens)
        return self.decode(enc_c, enc_s)

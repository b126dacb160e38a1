"""Token swapping: the soft swapper of eq. 4, its hard (argmax) ablation, eq. 19, and a time-coherent variant.

The similarity is the plain dot product (no 1/sqrt(d) scaling, eq. 4) between decoded content tokens and
the encoded style tokens, or optionally (``similarity="scaled"``) the dot product of LayerNorm-ed tokens
divided by sqrt(d); the blend is applied to the *raw* style tokens g^s (not the encoded ones), so every
output token is a convex combination of style tokens.

``coherent_swap_weights`` (not in the paper) takes the style tokens along one constant-rate path through
the style clip, chosen by the same similarities: the swap's per-token choices jump back and forth in the
style clip, and the half-overlapping tokens of the cross-fade then blend unrelated frames.

References: Kuriyama et al. 2022, §3.4, eq. 4; §4.3, eq. 19.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp


SIMILARITIES = ("dot", "scaled")
_MASKED = -1e9  # logit of a padded style token: exp underflows to exactly 0 next to any real token


def _standardize(x: jax.Array, eps: float = 1e-5) -> jax.Array:
    """LayerNorm without parameters over the last axis."""
    mu = jnp.mean(x, axis=-1, keepdims=True)
    var = jnp.var(x, axis=-1, keepdims=True)
    return (x - mu) * jax.lax.rsqrt(var + eps)


def swap_logits(decoded_content: jax.Array, encoded_style: jax.Array, similarity: str = "dot",
                style_valid=None) -> jax.Array:
    """Similarities ``(batch, Nc, Ns)`` of decoded content ``(batch, Nc, d)`` and encoded style tokens.

    encoded_style is the encoder output ``(batch, 1 + Ns, d)`` with CLS first; the CLS row is excluded.
    similarity: ``"dot"`` -- the plain dot product of eq. 4; ``"scaled"`` -- both sides normalised like a
    LayerNorm without parameters and divided by sqrt(d) (a cosine-like score in [-sqrt(d), sqrt(d)], so the
    softmax cannot become one-hot from growing token norms alone). style_valid: optional ``(batch, Ns)`` bool
    of the real style tokens of a padded set; padded columns get a logit of -1e9 (weight 0, never the argmax).
    """
    chex.assert_rank([decoded_content, encoded_style], 3)
    chex.assert_axis_dimension(encoded_style, 2, decoded_content.shape[-1])
    c, s = decoded_content, encoded_style[:, 1:]
    if similarity == "scaled":
        c, s = _standardize(c) / jnp.sqrt(c.shape[-1]).astype(c.dtype), _standardize(s)
    elif similarity != "dot":
        raise ValueError(f"unknown swap similarity {similarity!r} (expected one of {SIMILARITIES})")
    logits = jnp.einsum("bnd,bmd->bnm", c, s)
    if style_valid is not None:
        chex.assert_shape(style_valid, s.shape[:2])
        logits = jnp.where(style_valid.astype(bool)[:, None, :], logits, _MASKED)
    return logits


def soft_swap_weights(decoded_content: jax.Array, encoded_style: jax.Array,
                      temperature: float = 1.0, similarity: str = "dot", style_valid=None) -> jax.Array:
    """W = softmax_m(g~c_n . T_E(g^s)_m / temperature) over style tokens (CLS excluded); ``(batch, Nc, Ns)``.

    temperature = 1 is eq. 4; temperature -> 0 tends to the hard swap of eq. 19.
    References: Kuriyama et al. 2022, eq. 4.
    """
    logits = swap_logits(decoded_content, encoded_style, similarity, style_valid)
    weights = jax.nn.softmax(logits / temperature, axis=-1)
    if style_valid is not None:  # exp(-1e9) already underflows to 0; this keeps it exact at any temperature
        weights = jnp.where(style_valid.astype(bool)[:, None, :], weights, 0.0)
    return weights


def hard_swap_weights(decoded_content: jax.Array, encoded_style: jax.Array, similarity: str = "dot",
                      style_valid=None) -> jax.Array:
    """One-hot argmax over style tokens of the same similarities; ``(batch, Nc, Ns)``.

    References: Kuriyama et al. 2022, eq. 19.
    """
    logits = swap_logits(decoded_content, encoded_style, similarity, style_valid)
    return jax.nn.one_hot(jnp.argmax(logits, axis=-1), logits.shape[-1], dtype=logits.dtype)


#: rates (style tokens per content token) :func:`constant_rate_path` searches: 0.5 (half speed) .. 2.0
COHERENT_RATES = tuple(round(0.5 + 0.05 * i, 2) for i in range(31))


def constant_rate_path(scores: jax.Array, rates=COHERENT_RATES, valid=None, query_valid=None) -> jax.Array:
    """The style-token indices ``(batch, Nc)`` of the constant-rate path with the highest mean score.

    scores ``(batch, Nc, Ns)``: how well style token m fits content token n (e.g. log swap weights). Paths
    ``idx_n = min(round(s + r n), Ns - 1)`` for every rate r in ``rates`` and start s in 0 .. Ns - 1; a path
    may overrun the style's end by one token at most (it then holds the last token) unless no path fits, when
    every path counts. Ties go to the first (rate, start) in that order. valid: optional ``(batch, Ns)`` bool,
    the real style tokens of a padded set, which must come first: Ns is then their number per row, so the
    paths, their ends and the ties are those of the unpadded set and no path touches a padded token.
    query_valid: optional ``(batch, Nc)`` bool, the real content tokens (first): only they are scored and the
    path ends at the last of them (padded content tokens continue the path; their output is cut off).
    Not in the paper: a time-coherent choice of the tokens eq. 4 blends.
    References: Kuriyama et al. 2022, eq. 4 (the scores); eq. 1 (tokens).
    """
    chex.assert_rank(scores, 3)
    b, nc, ns = scores.shape
    if valid is None:
        n_real = jnp.full((b,), ns, jnp.int32)
    else:
        chex.assert_shape(valid, (b, ns))
        n_real = jnp.maximum(jnp.sum(valid.astype(jnp.int32), axis=-1), 1)
    r = jnp.asarray(rates, jnp.float32)[:, None, None]
    starts = jnp.arange(ns, dtype=jnp.float32)[None, :, None]
    steps = jnp.arange(nc, dtype=jnp.float32)[None, None, :]
    raw = jnp.round(starts + r * steps).astype(jnp.int32)  # (R, S, Nc)
    idx = jnp.minimum(raw[None], n_real[:, None, None, None] - 1)  # (batch, R, S, Nc)
    picked = jnp.take_along_axis(scores[:, None, None], idx[..., None], axis=-1)[..., 0]
    if query_valid is None:
        mean = jnp.mean(picked, axis=-1)  # (batch, R, S)
        last = jnp.broadcast_to(raw[None, ..., -1], mean.shape)
    else:
        chex.assert_shape(query_valid, (b, nc))
        q = query_valid.astype(scores.dtype)[:, None, None, :]
        rows = jnp.maximum(jnp.sum(query_valid.astype(jnp.int32), axis=-1), 1)  # (batch,)
        mean = jnp.sum(picked * q, axis=-1) / rows[:, None, None].astype(scores.dtype)
        last = jnp.take_along_axis(jnp.broadcast_to(raw[None], (b,) + raw.shape),
                                   jnp.broadcast_to((rows - 1)[:, None, None, None], (b,) + raw.shape[:2] + (1,)),
                                   axis=-1)[..., 0]
    started = (jnp.arange(ns)[None, None, :] < n_real[:, None, None])  # starts inside the real tokens
    fits = (last <= n_real[:, None, None]) & started
    any_fits = jnp.any(fits, axis=(1, 2), keepdims=True)
    mean = jnp.where(started, mean, -jnp.inf)
    mean = jnp.where(any_fits, jnp.where(fits, mean, -jnp.inf), mean)
    best = jnp.argmax(mean.reshape(b, -1), axis=-1)
    return idx.reshape(b, -1, nc)[jnp.arange(b), best]


def coherent_swap_weights(decoded_content: jax.Array, encoded_style: jax.Array, temperature: float = 1.0,
                          similarity: str = "dot", style_valid=None, rates=COHERENT_RATES,
                          content_valid=None) -> jax.Array:
    """One-hot weights ``(batch, Nc, Ns)`` on the :func:`constant_rate_path` of the log soft-swap weights.

    The similarities and softmax of eq. 4 (``temperature``, ``similarity``, ``style_valid`` as in
    :func:`soft_swap_weights`); each content token takes the one style token on the path, which never touches
    a padded token (``style_valid``: real tokens first; ``content_valid``: the real content tokens, the only
    ones scored). Not in the paper.
    References: Kuriyama et al. 2022, eq. 4.
    """
    logits = swap_logits(decoded_content, encoded_style, similarity, style_valid)
    path = constant_rate_path(jax.nn.log_softmax(logits / temperature, axis=-1), rates,
                              None if style_valid is None else style_valid.astype(bool),
                              None if content_valid is None else content_valid.astype(bool))
    return jax.nn.one_hot(path, logits.shape[-1], dtype=logits.dtype)


def nearest_token_weights(content_tokens: jax.Array, style_tokens: jax.Array, temperature: float = 0.0,
                          style_valid=None) -> jax.Array:
    """Oracle swap weights ``(batch, Nc, Ns)`` from squared Euclidean distances of RAW tokens (no transformer).

    temperature = 0: one-hot on the style token nearest to each content token; > 0: softmax of
    ``-d^2 / (temperature * s)`` with s the median over content tokens of their nearest squared distance (so
    the temperature is relative to the clip pair's own scale). A diagnostic upper bound on how much content a
    collage of style tokens can keep when the choice is made by content similarity in latent space, not a
    method of the paper. style_valid: optional ``(batch, Ns)`` bool (padded tokens get weight 0).
    References: Kuriyama et al. 2022, eq. 4 (the swap whose choice this replaces).
    """
    chex.assert_rank([content_tokens, style_tokens], 3)
    chex.assert_axis_dimension(style_tokens, 2, content_tokens.shape[-1])
    d2 = (jnp.sum(content_tokens ** 2, -1)[:, :, None] + jnp.sum(style_tokens ** 2, -1)[:, None, :]
          - 2.0 * jnp.einsum("bnd,bmd->bnm", content_tokens, style_tokens))
    d2 = jnp.maximum(d2, 0.0)
    if style_valid is not None:
        chex.assert_shape(style_valid, style_tokens.shape[:2])
        d2 = jnp.where(style_valid.astype(bool)[:, None, :], d2, jnp.inf)
    if temperature <= 0:
        return jax.nn.one_hot(jnp.argmin(d2, axis=-1), d2.shape[-1], dtype=content_tokens.dtype)
    scale = jnp.median(jnp.min(d2, axis=-1), axis=-1)[:, None, None] + 1e-9
    return jax.nn.softmax(-d2 / (temperature * scale), axis=-1)


def apply_swap(weights: jax.Array, style_tokens: jax.Array) -> jax.Array:
    """Blend raw style tokens: ``(batch, Nc, Ns) x (batch, Ns, d) -> (batch, Nc, d)``."""
    chex.assert_rank([weights, style_tokens], 3)
    chex.assert_axis_dimension(weights, 2, style_tokens.shape[1])
    return jnp.einsum("bnm,bmd->bnd", weights, style_tokens)


def soft_swap(decoded_content: jax.Array, encoded_style: jax.Array, style_tokens: jax.Array,
              temperature: float = 1.0) -> jax.Array:
    """g^{s|c} = softmax(g~c . T_E(g^s)) g^s: style-transferred tokens ``(batch, Nc, d)``.

    decoded_content ``(batch, Nc, d)``, encoded_style ``(batch, 1 + Ns, d)`` (CLS first), style_tokens
    ``(batch, Ns, d)`` (raw tokens that were encoded). References: Kuriyama et al. 2022, eq. 4.
    """
    chex.assert_axis_dimension(encoded_style, 1, style_tokens.shape[1] + 1)
    return apply_swap(soft_swap_weights(decoded_content, encoded_style, temperature), style_tokens)


def hard_swap(decoded_content: jax.Array, encoded_style: jax.Array, style_tokens: jax.Array) -> jax.Array:
    """Each content token replaced by the single most similar style token (argmax of eq. 19).

    References: Kuriyama et al. 2022, eq. 19.
    """
    chex.assert_axis_dimension(encoded_style, 1, style_tokens.shape[1] + 1)
    return apply_swap(hard_swap_weights(decoded_content, encoded_style), style_tokens)

"""Token swapping: the soft swapper of eq. 4 and its hard (argmax) ablation, eq. 19.

The similarity is the plain dot product (no 1/sqrt(d) scaling) between decoded content tokens and the
encoded style tokens; the blend is applied to the *raw* style tokens g^s (not the encoded ones), so every
output token is a convex combination of style tokens.

References: Kuriyama et al. 2022, §3.4, eq. 4; §4.3, eq. 19.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp


def swap_logits(decoded_content: jax.Array, encoded_style: jax.Array) -> jax.Array:
    """Dot products ``(batch, Nc, Ns)`` of decoded content ``(batch, Nc, d)`` and encoded style tokens.

    encoded_style is the encoder output ``(batch, 1 + Ns, d)`` with CLS first; the CLS row is excluded.
    """
    chex.assert_rank([decoded_content, encoded_style], 3)
    chex.assert_axis_dimension(encoded_style, 2, decoded_content.shape[-1])
    return jnp.einsum("bnd,bmd->bnm", decoded_content, encoded_style[:, 1:])


def soft_swap_weights(decoded_content: jax.Array, encoded_style: jax.Array,
                      temperature: float = 1.0) -> jax.Array:
    """W = softmax_m(g~c_n . T_E(g^s)_m / temperature) over style tokens (CLS excluded); ``(batch, Nc, Ns)``.

    temperature = 1 is eq. 4; temperature -> 0 tends to the hard swap of eq. 19.
    References: Kuriyama et al. 2022, eq. 4.
    """
    return jax.nn.softmax(swap_logits(decoded_content, encoded_style) / temperature, axis=-1)


def hard_swap_weights(decoded_content: jax.Array, encoded_style: jax.Array) -> jax.Array:
    """One-hot argmax over style tokens of the same similarities; ``(batch, Nc, Ns)``.

    References: Kuriyama et al. 2022, eq. 19.
    """
    logits = swap_logits(decoded_content, encoded_style)
    return jax.nn.one_hot(jnp.argmax(logits, axis=-1), logits.shape[-1], dtype=logits.dtype)


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

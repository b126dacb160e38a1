"""Losses of the style transformer (eqs. 5-12). Pure functions returning per-example values ``(batch,)``.

The autoencoder's reconstruction loss lives with the autoencoder (``autoencoder.expmap_reconstruction_loss``).

References: Kuriyama et al. 2022, §3.5, eqs. 5-12 (and the authors' public code for the reductions).
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp

from jaxgest.nn import safe_norm

_EPS = 1e-8


def token_norm(x: jax.Array) -> jax.Array:
    """||x||_tau: the L2 norm of every token averaged over tokens; ``(batch, N, d) -> (batch,)``.

    References: Kuriyama et al. 2022, §3.5 ("averaged L2-norm computed per each token").
    """
    chex.assert_rank(x, 3)
    return jnp.mean(safe_norm(x), axis=1)


def identity_loss(content_identity: jax.Array, content_tokens: jax.Array, style_identity: jax.Array,
                  style_tokens: jax.Array) -> jax.Array:
    """L_identity = ||g^{c|c} - g^c||_tau + ||g^{s|s} - g^s||_tau; ``(batch,)``.

    content_identity: content transferred with itself as style ``(batch, Nc, d)``; likewise for style.
    References: Kuriyama et al. 2022, eq. 5.
    """
    chex.assert_equal_shape([content_identity, content_tokens])
    chex.assert_equal_shape([style_identity, style_tokens])
    return token_norm(content_identity - content_tokens) + token_norm(style_identity - style_tokens)


def cyclic_loss(cyclic_tokens: jax.Array, content_tokens: jax.Array) -> jax.Array:
    """L_cyclic = ||g^{c|s|c} - g^c||_tau (content -> style -> back with the content as style); ``(batch,)``.

    References: Kuriyama et al. 2022, eqs. 6-8.
    """
    chex.assert_equal_shape([cyclic_tokens, content_tokens])
    return token_norm(cyclic_tokens - content_tokens)


def structure_matrix(keys: jax.Array) -> jax.Array:
    """m(g): cosine self-similarity of encoder keys, ``(batch, N, d) -> (batch, N, N)``.

    ``keys`` are the gesture-token keys k_i = m_k g_i of the encoder (CLS excluded, as in SPEC.md; the
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

"""Baselines of the comparison in §4.3: AdaIN on latents (eq. 17), Avatar-net-like token swap (eq. 18)
and the hard swap (eq. 19, :func:`jaxgest.tgst.swap.hard_swap`, re-exported here).

Statistics are per latent channel over time. ``content_valid`` / ``style_valid`` (static ints) restrict
them to the latent frames of the real clip, so the edge padding added to reach a multiple of 16 frames
does not bias them. The standard deviation is the population one (ddof = 0) so that the AdaIN output has
exactly the style's mean and std; the authors' code uses ``torch.std`` (ddof = 1).

References: Kuriyama et al. 2022, §4.3, eqs. 17-19; Huang & Belongie 2017 (AdaIN); Sheng et al. 2018.
"""

from __future__ import annotations

from typing import Optional

import chex
import jax
import jax.numpy as jnp

from jaxgest.tgst.swap import hard_swap  # noqa: F401  (eq. 19 baseline, same API as the soft swap)
from jaxgest.tgst.tokens import detokenize, tokenize

_EPS = 1e-6


def latent_stats(z: jax.Array, valid: Optional[int] = None) -> tuple[jax.Array, jax.Array]:
    """Per-channel mean and std over the first ``valid`` frames: ``(batch, T, d) -> 2 x (batch, 1, d)``."""
    chex.assert_rank(z, 3)
    zv = z if valid is None else z[:, :valid]
    return jnp.mean(zv, axis=1, keepdims=True), jnp.std(zv, axis=1, keepdims=True)


def adain_latents(content_z: jax.Array, style_z: jax.Array, *, content_valid: Optional[int] = None,
                  style_valid: Optional[int] = None, eps: float = _EPS) -> jax.Array:
    """z^x_i = sigma(z^s) (z^c_i - mu(z^c)) / sigma(z^c) + mu(z^s); ``(batch, Tc, d)``.

    References: Kuriyama et al. 2022, eq. 17.
    """
    chex.assert_rank([content_z, style_z], 3)
    mu_c, sd_c = latent_stats(content_z, content_valid)
    mu_s, sd_s = latent_stats(style_z, style_valid)
    return sd_s * (content_z - mu_c) / (sd_c + eps) + mu_s


def cosine_argmax_swap(content_tokens: jax.Array, style_tokens: jax.Array) -> jax.Array:
    """Replace each content token by the style token of maximal cosine similarity; ``(batch, Nc, d)``.

    Eq. 18 prints ``argmax arccos(.)``, which would pick the *least* similar token; the text ("the most
    similar style token") and the authors' code use the argmax of the cosine itself, as here.
    References: Kuriyama et al. 2022, eq. 18.
    """
    chex.assert_rank([content_tokens, style_tokens], 3)
    unit = lambda t: t / jnp.maximum(jnp.linalg.norm(t, axis=-1, keepdims=True), _EPS)  # noqa: E731
    sim = jnp.einsum("bnd,bmd->bnm", unit(content_tokens), unit(style_tokens))
    idx = jnp.argmax(sim, axis=-1)
    return jnp.take_along_axis(style_tokens, idx[..., None], axis=1)


def avatarnet_swap(content_z: jax.Array, style_z: jax.Array, *, w: int = 4, h: int = 2,
                   content_valid: Optional[int] = None, style_valid: Optional[int] = None,
                   eps: float = _EPS) -> jax.Array:
    """Whiten both latents by their own mean/std, swap tokens by cosine argmax, re-colour with the style's.

    content_z ``(batch, Tc, d)``, style_z ``(batch, Ts, d)`` -> ``(batch, Tc, d)``; the swapped tokens are
    merged by the same linear cross-fade as the soft swap. References: Kuriyama et al. 2022, eq. 18;
    Sheng et al. 2018 (Avatar-net's style decorator, here with per-channel whitening as in the authors' code).
    """
    chex.assert_rank([content_z, style_z], 3)
    mu_c, sd_c = latent_stats(content_z, content_valid)
    mu_s, sd_s = latent_stats(style_z, style_valid)
    c_white = (content_z - mu_c) / (sd_c + eps)
    s_white = (style_z - mu_s) / (sd_s + eps)
    swapped = cosine_argmax_swap(tokenize(c_white, w, h), tokenize(s_white, w, h))
    return sd_s * detokenize(swapped, content_z.shape[1], w, h) + mu_s

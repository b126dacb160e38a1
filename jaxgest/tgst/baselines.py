"""Baselines of the comparison in §4.3: AdaIN on latents (eq. 17), Avatar-net-like token swap (eq. 18)
and the hard swap (eq. 19, :func:`jaxgest.tgst.swap.hard_swap`, re-exported here).

Statistics are per latent channel over time. ``content_valid`` / ``style_valid`` (ints or (start, stop) ranges) restrict
them to the latent frames of the real clip, so the edge padding added to reach a multiple of 16 frames
does not bias them. The standard deviation is the population one (ddof = 0) so that the AdaIN output has
exactly the style's mean and std; the authors' code uses ``torch.std`` (ddof = 1).

The second half holds the reconstruction baselines that the autoencoder is compared with (PCA of 4-frame
blocks with the same latent budget, the constant mean pose, per-joint angle errors).

References: Kuriyama et al. 2022, §4.3, eqs. 17-19; Huang & Belongie 2017 (AdaIN); Sheng et al. 2018.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.motion import rotations
from jaxgest.motion.rotations import angular_error_rad
from jaxgest.tgst.swap import hard_swap  # noqa: F401  (eq. 19 baseline, same API as the soft swap)
from jaxgest.tgst.tokens import detokenize, tokenize

_EPS = 1e-6


def latent_stats(z: jax.Array, valid=None) -> tuple[jax.Array, jax.Array]:
    """Per-channel mean and std over the valid frames: ``(batch, T, d) -> 2 x (batch, 1, d)``.

    valid: None (all frames), an int (the first ``valid`` frames) or a ``(start, stop)`` range; static ints
    slice, traced ones (scalars or ``(batch,)``, e.g. the real length of a clip padded to a length bucket)
    mask, with the same result.
    """
    chex.assert_rank(z, 3)
    if valid is None:
        return jnp.mean(z, axis=1, keepdims=True), jnp.std(z, axis=1, keepdims=True)
    start, stop = valid if isinstance(valid, tuple) else (0, valid)
    if isinstance(start, int) and isinstance(stop, int):
        zv = z[:, start:stop]
        return jnp.mean(zv, axis=1, keepdims=True), jnp.std(zv, axis=1, keepdims=True)
    t = jnp.arange(z.shape[1])[None, :]
    m = (t >= jnp.reshape(jnp.asarray(start), (-1, 1))) & (t < jnp.reshape(jnp.asarray(stop), (-1, 1)))
    m = m[..., None].astype(z.dtype)
    n = jnp.maximum(jnp.sum(m, axis=1, keepdims=True), 1.0)
    mu = jnp.sum(z * m, axis=1, keepdims=True) / n
    return mu, jnp.sqrt(jnp.sum(jnp.square(z - mu) * m, axis=1, keepdims=True) / n)


def adain_latents(content_z: jax.Array, style_z: jax.Array, *, content_valid=None, style_valid=None,
                  eps: float = _EPS) -> jax.Array:
    """z^x_i = sigma(z^s) (z^c_i - mu(z^c)) / sigma(z^c) + mu(z^s); ``(batch, Tc, d)``.

    References: Kuriyama et al. 2022, eq. 17.
    """
    chex.assert_rank([content_z, style_z], 3)
    mu_c, sd_c = latent_stats(content_z, content_valid)
    mu_s, sd_s = latent_stats(style_z, style_valid)
    return sd_s * (content_z - mu_c) / (sd_c + eps) + mu_s


def cosine_argmax_swap(content_tokens: jax.Array, style_tokens: jax.Array, style_valid=None) -> jax.Array:
    """Replace each content token by the style token of maximal cosine similarity; ``(batch, Nc, d)``.

    Eq. 18 prints ``argmax arccos(.)``, which would pick the *least* similar token; the text ("the most
    similar style token") and the authors' code use the argmax of the cosine itself, as here. style_valid:
    optional ``(batch, Ns)`` bool of the real style tokens of a padded set (padded ones are never chosen).
    References: Kuriyama et al. 2022, eq. 18.
    """
    chex.assert_rank([content_tokens, style_tokens], 3)
    unit = lambda t: t / jnp.maximum(jnp.linalg.norm(t, axis=-1, keepdims=True), _EPS)  # noqa: E731
    sim = jnp.einsum("bnd,bmd->bnm", unit(content_tokens), unit(style_tokens))
    if style_valid is not None:
        chex.assert_shape(style_valid, style_tokens.shape[:2])
        sim = jnp.where(style_valid.astype(bool)[:, None, :], sim, -jnp.inf)
    idx = jnp.argmax(sim, axis=-1)
    return jnp.take_along_axis(style_tokens, idx[..., None], axis=1)


def avatarnet_swap(content_z: jax.Array, style_z: jax.Array, *, w: int = 4, h: int = 2,
                   content_valid=None, style_valid=None, style_token_valid=None,
                   eps: float = _EPS) -> jax.Array:
    """Whiten both latents by their own mean/std, swap tokens by cosine argmax, re-colour with the style's.

    content_z ``(batch, Tc, d)``, style_z ``(batch, Ts, d)`` -> ``(batch, Tc, d)``; the swapped tokens are
    merged by the same linear cross-fade as the soft swap. ``style_token_valid``: optional ``(batch, Ns)`` bool
    of the real style tokens (:func:`cosine_argmax_swap`). References: Kuriyama et al. 2022, eq. 18;
    Sheng et al. 2018 (Avatar-net's style decorator, here with per-channel whitening as in the authors' code).
    """
    chex.assert_rank([content_z, style_z], 3)
    mu_c, sd_c = latent_stats(content_z, content_valid)
    mu_s, sd_s = latent_stats(style_z, style_valid)
    c_white = (content_z - mu_c) / (sd_c + eps)
    s_white = (style_z - mu_s) / (sd_s + eps)
    swapped = cosine_argmax_swap(tokenize(c_white, w, h), tokenize(s_white, w, h), style_token_valid)
    return sd_s * detokenize(swapped, content_z.shape[1], w, h) + mu_s


# ---------------------------------------------------------------------------------------------------------
# Reconstruction baselines of the autoencoder (diagnostics, not in the paper): what a linear code of the same
# size, and the constant mean pose, achieve on the same clips.

def block_pca_fit(clips, *, components: int = 16, frames: int = 4) -> dict:
    """PCA of non-overlapping ``frames``-frame blocks of exp-maps: the autoencoder's latent budget.

    clips: arrays ``(F_i, C)``; every whole block of every clip is a sample of ``frames * C`` numbers.
    ``components`` numbers per ``frames`` frames is the paper autoencoder's budget (16 latents per 4 frames).
    Returns ``{"mean": (frames * C,), "basis": (components, frames * C), "frames": frames}`` (numpy).
    """
    blocks = np.concatenate([_blocks(np.asarray(c, np.float64), frames) for c in clips], axis=0)
    mean = blocks.mean(0)
    _, _, vt = np.linalg.svd(blocks - mean, full_matrices=False)
    return {"mean": mean, "basis": vt[:components], "frames": frames}


def _blocks(x: np.ndarray, frames: int) -> np.ndarray:
    f = x.shape[0] // frames * frames
    return x[:f].reshape(-1, frames * x.shape[1])


def block_pca_reconstruct(pca: dict, x) -> np.ndarray:
    """``(F, C)`` -> its reconstruction from ``components`` numbers per block (the end padded by its edge)."""
    x = np.asarray(x, np.float64)
    k = pca["frames"]
    f = x.shape[0]
    fp = -(-f // k) * k
    xp = np.concatenate([x, np.repeat(x[-1:], fp - f, axis=0)], axis=0)
    b = _blocks(xp, k) - pca["mean"]
    rec = (b @ pca["basis"].T) @ pca["basis"] + pca["mean"]
    return rec.reshape(fp, x.shape[1])[:f].astype(np.float32)


def mean_pose_fit(clips) -> np.ndarray:
    """The mean pose of ``clips`` ``(F_i, 3J)`` exp-maps: the constant predictor, ``(3J,)``.

    Per joint the rotation mean of every frame (the principal eigenvector of sum q q^T over unit quaternions,
    sign-free), returned as an exp-map. (The channel mean of exp-maps would be wrong for joints near a
    rotation of pi, where the exp-map jumps to the antipode: the rig's arm and leg frames sit there.)
    """
    x = np.concatenate([np.asarray(c, np.float64) for c in clips], axis=0)
    q = np.asarray(rotations.expmap_to_quat(x.reshape(len(x), -1, 3)))  # (N, J, 4)
    mean = []
    for j in range(q.shape[1]):
        _, vecs = np.linalg.eigh(q[:, j].T @ q[:, j])
        mean.append(vecs[:, -1])
    return np.asarray(rotations.quat_to_expmap(np.stack(mean)), np.float32).reshape(-1)


def per_joint_angle_deg(pred, target) -> np.ndarray:
    """Mean geodesic angle in degrees per joint between exp-map arrays ``(F, 3J)`` -> ``(J,)``."""
    pred = np.broadcast_to(np.asarray(pred, np.float32), np.shape(target))
    return np.degrees(np.asarray(angular_error_rad(jnp.asarray(pred), jnp.asarray(target, jnp.float32)))).mean(0)

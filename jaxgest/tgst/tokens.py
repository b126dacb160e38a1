"""Gesture tokens: half-overlapping windows of latent frames (eq. 1) and their cross-faded inverse.

With w = 4 latent frames per token and stride h = w / 2 = 2, a token covers 16 motion frames (the encoder
halves time twice). Clips are padded at the end (edge values) so that every frame is covered, and trimmed
back afterwards, which makes ``detokenize(tokenize(z), T) == z`` exact for every T >= w.

References: Kuriyama et al. 2022, §3.3, eq. 1.
"""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp

from jaxgest.runtime.errors import DataError


class ClipTooShortError(DataError, ValueError):
    """A clip is shorter than one gesture token (16 frames for the paper's settings)."""


def check_clip_length(frames: int, *, min_frames: int = 16, what: str = "clip") -> None:
    """Raise :class:`ClipTooShortError` if ``frames < min_frames`` (static shapes: checked at trace time)."""
    if frames < min_frames:
        raise ClipTooShortError(
            f"{what} has {frames} frames; TGST needs at least {min_frames} frames (one gesture token)"
        )


def padded_length(frames: int, multiple: int) -> int:
    """Smallest multiple of ``multiple`` that is >= ``frames``."""
    return int(math.ceil(frames / multiple) * multiple)


def pad_frames(x: jax.Array, multiple: int = 16, *, min_frames: int = 16) -> jax.Array:
    """Pad ``(batch, F, ch)`` at the end by repeating the last frame up to a multiple of ``multiple`` frames.

    Raises :class:`ClipTooShortError` when ``F < min_frames``.
    """
    chex.assert_rank(x, 3)
    f = x.shape[1]
    check_clip_length(f, min_frames=min_frames)
    target = padded_length(f, multiple)
    if target == f:
        return x
    return jnp.pad(x, ((0, 0), (0, target - f), (0, 0)), mode="edge")


def trim_frames(x: jax.Array, frames: int) -> jax.Array:
    """Inverse of :func:`pad_frames`: keep the first ``frames`` frames of ``(batch, F, ch)``."""
    return x[:, :frames]


def num_tokens(latent_frames: int, *, w: int = 4, h: int = 2) -> int:
    """Number of tokens N = floor(T' / h) - 1 of a latent clip padded to T' = ceil(T / h) * h frames."""
    return padded_length(latent_frames, h) // h - 1


def tokenize(z: jax.Array, w: int = 4, h: int = 2) -> jax.Array:
    """Latents ``(batch, T, d_z)`` -> tokens ``(batch, N, w * d_z)``, g_n = z_{nh} ⊕ ... ⊕ z_{nh+w-1}.

    The end is padded (edge values) to a multiple of h so the last frames are covered; N = T'/h - 1.
    Needs w = 2h (half overlap) and T >= w.
    References: Kuriyama et al. 2022, eq. 1.
    """
    chex.assert_rank(z, 3)
    if w != 2 * h:
        raise ValueError(f"tokens must half-overlap (w = 2h), got w={w}, h={h}")
    b, t, d = z.shape
    check_clip_length(t, min_frames=w, what="latent clip")
    tp = padded_length(t, h)
    if tp != t:
        z = jnp.pad(z, ((0, 0), (0, tp - t), (0, 0)), mode="edge")
    chunks = z.reshape(b, tp // h, h, d)  # token n = chunk n followed by chunk n + 1
    tokens = jnp.concatenate([chunks[:, :-1], chunks[:, 1:]], axis=2)
    return tokens.reshape(b, tp // h - 1, w * d)


def crossfade_weights(h: int, dtype=jnp.float32) -> jax.Array:
    """Weights (h,) of the later token across an overlap of h latent frames: (j + 1) / (h + 1)."""
    return (jnp.arange(1, h + 1, dtype=dtype) / (h + 1)).astype(dtype)


def detokenize(tokens: jax.Array, length: int, w: int = 4, h: int = 2) -> jax.Array:
    """Gesture tokens ``(batch, N, w * d_z)`` -> latents ``(batch, length, d_z)`` by linear cross-fade.

    Each overlap of h latent frames between token n (second half) and token n+1 (first half) is blended
    with weights rising linearly from token n to token n+1 per latent frame ((j+1)/(h+1), j < h); the
    first and last half-tokens are used as they are. Exact inverse of :func:`tokenize` (overlaps agree).
    The authors' ``linear_blending`` ramps the weight over the 32 flattened values of a half token instead
    (0..1 per element); both are linear cross-fades, the per-frame one is independent of channel order.
    References: Kuriyama et al. 2022, §3.3 ("linearly interpolated to merge the overlapped regions").
    """
    chex.assert_rank(tokens, 3)
    if w != 2 * h:
        raise ValueError(f"tokens must half-overlap (w = 2h), got w={w}, h={h}")
    b, n, dg = tokens.shape
    d = dg // w
    total = (n + 1) * h
    if not (0 < length <= total):
        raise ValueError(f"cannot detokenize {n} tokens into {length} latent frames (at most {total})")
    halves = tokens.reshape(b, n, 2, h, d)
    first, second = halves[:, :, 0], halves[:, :, 1]  # (b, n, h, d)
    a = crossfade_weights(h, tokens.dtype)[None, None, :, None]
    middle = (1.0 - a) * second[:, :-1] + a * first[:, 1:]  # overlaps 1..n-1
    chunks = jnp.concatenate([first[:, :1], middle, second[:, -1:]], axis=1)  # (b, n + 1, h, d)
    return chunks.reshape(b, total, d)[:, :length]

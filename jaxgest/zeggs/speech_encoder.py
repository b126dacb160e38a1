"""ZeroEGGS speech encoder: speech features (B, T, 81) -> speech embedding S (B, T, D_S).

Two Conv1d layers over time (64 channels, kernels 3 and 31; "same" length with replicated edges as in
the authors' code), each followed by ELU and dropout 0.2, then a framewise linear layer with ELU (the
authors' code applies ELU to the output too). The receptive field is 33 frames (~0.55 s at 60 fps) on
each side in total; the paper aims at "roughly 1 second of speech".

References: Ghorbani et al. 2023, §3.1 (Fig. 3a) and §4.2.
"""

from __future__ import annotations

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp

from jaxgest.zeggs.config import ModelConfig


def replicate_pad(x: jax.Array, kernel: int) -> jax.Array:
    """Pad the time axis of ``(batch, frames, ch)`` by repeating the edge frames (PyTorch ``replicate``)."""
    left = (kernel - 1) // 2
    return jnp.pad(x, ((0, 0), (left, kernel - 1 - left), (0, 0)), mode="edge")


class SpeechEncoder(nn.Module):
    """Speech features ``(batch, frames, speech_dim)`` -> embeddings ``(batch, frames, D_S)``.

    References: Ghorbani et al. 2023, §3.1, §4.2.
    """

    cfg: ModelConfig

    @nn.compact
    def __call__(self, speech: jax.Array, *, deterministic: bool = True) -> jax.Array:
        cfg = self.cfg
        chex.assert_rank(speech, 3)
        chex.assert_axis_dimension(speech, 2, cfg.speech_dim)
        x = speech
        for i, (ch, k) in enumerate(zip(cfg.speech_channels, cfg.speech_kernels)):
            x = nn.Conv(ch, (k,), padding="VALID", name=f"conv{i}")(replicate_pad(x, k))
            x = nn.Dropout(cfg.speech_dropout)(nn.elu(x), deterministic=deterministic)
        s = nn.elu(nn.Dense(cfg.speech_embedding, name="linear")(x))
        chex.assert_shape(s, speech.shape[:2] + (cfg.speech_embedding,))
        return s

"""ZeroEGGS style encoder (a VAE posterior): style clip (B, M, P) + mask -> mu, log sigma^2 (B, D_e).

Architecture (Fig. 3b, after Daft-Exprt's prosody encoder, as in the authors' code):
Conv1d k3 512 -> ReLU -> LayerNorm -> dropout 0.2 -> Conv1d k3 2 D_e -> ReLU -> LayerNorm -> dropout 0.2;
sinusoidal positional encoding over the frame index; one feed-forward transformer (FFT) block = 4-head
self-attention (dropout 0.1) + residual + LayerNorm, then two Conv1d k3 (ReLU between, dropout 0.1) +
residual + LayerNorm; mean over the real frames; the first D_e channels are mu, the last D_e log sigma^2.

Padding: a batch of clips of unequal lengths is padded at the end and carries a mask (True = real frame).
Padded frames are zeroed before every conv (so a conv at a clip's last frame sees the same zeros as the
"same" padding of that clip alone), excluded as attention keys and from the mean: every clip gets the
same (mu, logvar) as when encoded alone.

References: Ghorbani et al. 2023, §3.2 (Fig. 3b) and §4.2; Zaidi et al. 2021 (Daft-Exprt FFT block);
Vaswani et al. 2017 (sinusoidal positions); Kingma & Welling 2013 (reparameterisation).
"""

from __future__ import annotations

from typing import Optional

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp

from jaxgest.nn import sinusoidal_positions
from jaxgest.zeggs.config import ModelConfig


def masked_mean(x: jax.Array, mask: jax.Array) -> jax.Array:
    """Mean over frames of ``(batch, frames, ch)`` counting only frames where ``mask (batch, frames)``."""
    m = mask.astype(x.dtype)[..., None]
    return jnp.sum(x * m, axis=1) / jnp.maximum(jnp.sum(m, axis=1), 1.0)


def sample_style(mu: jax.Array, logvar: jax.Array, key: jax.Array, temperature: float = 1.0) -> jax.Array:
    """Reparameterised sample ``e = mu + temperature * sigma * eps``, ``eps ~ N(0, I)``; (batch, D_e).

    ``temperature`` scales the posterior's standard deviation (0 gives mu, 1 the trained posterior). The
    authors' code divides sigma by its "temperature" instead; the paper leaves it open (docs/design.md §4 asks for
    a temperature at inference), we use the usual multiplicative convention.
    References: Kingma & Welling 2013, §2.4; Ghorbani et al. 2023, §3.2.
    """
    eps = jax.random.normal(key, mu.shape, mu.dtype)
    return mu + jnp.asarray(temperature, mu.dtype) * jnp.exp(0.5 * logvar) * eps


class FFTBlock(nn.Module):
    """Feed-forward transformer block: masked MHA + res + LN, conv FF + res + LN; (batch, frames, d)."""

    heads: int
    kernel: int
    dropout: float

    @nn.compact
    def __call__(self, x: jax.Array, mask: jax.Array, *, deterministic: bool) -> jax.Array:
        d = x.shape[-1]
        m = mask[..., None].astype(x.dtype)
        attn = nn.MultiHeadDotProductAttention(
            num_heads=self.heads, dropout_rate=self.dropout, deterministic=deterministic, name="attention"
        )(x, x, mask=nn.make_attention_mask(mask, mask))
        attn = nn.Dropout(self.dropout)(attn, deterministic=deterministic)
        h = nn.LayerNorm(name="attention_norm")(attn + x) * m
        f = nn.relu(nn.Conv(d, (self.kernel,), padding="SAME", name="ff_conv0")(h)) * m
        f = nn.Conv(d, (self.kernel,), padding="SAME", name="ff_conv1")(f)
        f = nn.Dropout(self.dropout)(f, deterministic=deterministic)
        return nn.LayerNorm(name="ff_norm")(f + h) * m


class StyleEncoder(nn.Module):
    """Style clip ``(batch, frames, P)`` and mask ``(batch, frames)`` -> ``(mu, logvar)`` each ``(batch, D_e)``.

    References: Ghorbani et al. 2023, §3.2, §4.2.
    """

    cfg: ModelConfig

    @nn.compact
    def __call__(self, style: jax.Array, mask: Optional[jax.Array] = None, *,
                 deterministic: bool = True) -> tuple[jax.Array, jax.Array]:
        cfg = self.cfg
        chex.assert_rank(style, 3)
        chex.assert_axis_dimension(style, 2, cfg.pose_dim)
        b, frames, _ = style.shape
        if mask is None:
            mask = jnp.ones((b, frames), bool)
        chex.assert_shape(mask, (b, frames))
        mask = mask.astype(bool)
        m = mask[..., None].astype(style.dtype)
        d = cfg.style_model_dim
        x = style * m
        for i, ch in enumerate((cfg.style_hidden, d)):
            x = nn.Conv(ch, (cfg.style_kernel,), padding="SAME", name=f"conv{i}")(x)
            x = nn.LayerNorm(name=f"conv{i}_norm")(nn.relu(x))
            x = nn.Dropout(cfg.style_dropout)(x, deterministic=deterministic) * m
        x = (x + sinusoidal_positions(frames, d)[None]) * m
        x = FFTBlock(cfg.style_heads, cfg.style_kernel, cfg.style_attention_dropout, name="fft")(
            x, mask, deterministic=deterministic)
        if cfg.style_projection:
            x = nn.Dense(d, name="projection")(x)
        pooled = masked_mean(x, mask)
        mu, logvar = pooled[:, : cfg.style_embedding], pooled[:, cfg.style_embedding:]
        chex.assert_shape([mu, logvar], (b, cfg.style_embedding))
        return mu, logvar

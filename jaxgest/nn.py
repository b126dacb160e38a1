"""Small numerical building blocks shared by both models (TGST and ZeroEGGS).

References: Vaswani et al. 2017, §3.5 (sinusoidal positions); Kuriyama et al. 2022, eq. 2 (the same
positions over the token index); Ghorbani et al. 2023, §3.2 (positions in the style encoder).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np


def sinusoidal_positions(num: int, dim: int, *, angle_scale: float = 1.0,
                         timescale: float = 10000.0) -> np.ndarray:
    """Positions ``(num, dim)`` float32: pe[p, 2i] = sin(s p f_i), pe[p, 2i+1] = cos(s p f_i),
    f_i = timescale^(-2i/dim).

    ``angle_scale`` s is 1 for Vaswani et al. (and ZeroEGGS); the TGST authors' code uses 2*pi. Computed in
    float64 with NumPy: a constant under ``jax.jit`` (``num`` and ``dim`` are static shapes).
    References: Vaswani et al. 2017, §3.5; Kuriyama et al. 2022, eq. 2.
    """
    pos = np.arange(num, dtype=np.float64)[:, None] * angle_scale
    freq = np.exp(np.arange(0, dim, 2, dtype=np.float64) * (-math.log(timescale) / dim))
    pe = np.zeros((num, dim), dtype=np.float64)
    pe[:, 0::2] = np.sin(pos * freq)
    pe[:, 1::2] = np.cos(pos * freq[: dim // 2])
    return pe.astype(np.float32)


def safe_norm(x: jax.Array, axis: int = -1) -> jax.Array:
    """L2 norm over ``axis`` with a zero (not NaN) gradient at 0, like ``torch.norm``."""
    sq = jnp.sum(x * x, axis=axis)
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def gelu_exact(x: jax.Array) -> jax.Array:
    """Exact GELU ``x Phi(x) = x / 2 (1 + erf(x / sqrt 2))``, as ``torch.nn.GELU()`` computes it.

    The same function as ``jax.nn.gelu(x, approximate=False)`` (within 1e-6 absolute in float32), which
    evaluates ``erfc`` instead: XLA CPU expands that into three polynomial branches, an exponential and two
    divisions per element, ~2.6x the cost of ``erf`` (one rational polynomial). With 3 M activations per
    TGST transfer of 8 x 1280 frames the GELUs were ~20 % of its CPU time.
    References: Hendrycks & Gimpel 2016 (GELU).
    """
    return 0.5 * x * (1.0 + jax.lax.erf(x * (1.0 / math.sqrt(2.0))))

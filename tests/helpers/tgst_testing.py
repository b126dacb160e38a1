"""Shared pieces of the TGST model tests: the tiny config with a short band, smooth test motions and random
parameters of the model's structure."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.tgst.config import preset
from jaxgest.tgst.model import init_params

TINY = preset("tiny")
# omega = 2 so that the band matters on short test clips (7 tokens for 64 frames)
CFG = dataclasses.replace(TINY.model, transformer=dataclasses.replace(TINY.model.transformer, omega=2, block_size=4))
FULL = dataclasses.replace(TINY, model=CFG)  # the preset with that model, for the training steps


def normal(seed, shape, scale=1.0):
    return jnp.asarray(scale * np.random.default_rng(seed).normal(size=shape), jnp.float32)


def smooth_motion(seed, batch, frames, channels):
    """Smooth sinusoidal exp-maps (learnable by the conv autoencoder)."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[None, :, None] / 60.0
    freq, phase, amp = (rng.uniform(0.3, 2.0, (batch, 1, channels)), rng.uniform(0, 6, (batch, 1, channels)),
                        rng.uniform(0.1, 0.6, (batch, 1, channels)))
    return jnp.asarray(amp * np.sin(2 * np.pi * freq * t + phase), jnp.float32)


def random_like(shapes, seed=0):
    """Random parameters with the structure of ``shapes`` (kernels ~ N(0, 1/fan_in), LN scales 1, biases 0).

    Filled with NumPy: compiling Flax's initialisers costs seconds per model on this machine, and the
    initialisers themselves are not under test here (their structure is, via ``jax.eval_shape``).
    """
    rng = np.random.default_rng(seed)

    def fill(path, leaf):
        name = jax.tree_util.keystr(path)
        if "scale" in name:
            return jnp.ones(leaf.shape, leaf.dtype)
        if "bias" in name:
            return jnp.zeros(leaf.shape, leaf.dtype)
        fan_in = int(np.prod(leaf.shape[:-1])) if len(leaf.shape) > 1 else 1
        return jnp.asarray(rng.normal(size=leaf.shape) / np.sqrt(fan_in), leaf.dtype)

    return jax.tree_util.tree_map_with_path(fill, shapes)


def param_count(tree):
    return int(sum(x.size for x in jax.tree_util.tree_leaves(tree)))


@functools.lru_cache(maxsize=None)
def random_params(seed: int = 0):
    """Random parameters of the tiny TGST model with ``CFG`` (structure from ``init_params``; see
    :func:`random_like`). Treat as read-only (copy before donating)."""
    return random_like(jax.eval_shape(lambda k: init_params(CFG, k), jax.random.key(0)), seed=seed)

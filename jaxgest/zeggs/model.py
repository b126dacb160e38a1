"""The full ZeroEGGS network: speech encoder + style encoder (VAE) + generator, its dummy inputs and init.

``ZeggsModel(cfg)`` (``cfg`` a :class:`jaxgest.zeggs.config.ModelConfig`) has the methods
``encode_speech``, ``encode_style``, ``generate`` and ``__call__`` (all three); its parameters are
``{"speech_encoder", "style_encoder", "generator"}`` (:func:`init_params`).

References: Ghorbani et al. 2023, §3 (Fig. 2).
"""

from __future__ import annotations

import functools
from typing import Optional

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.zeggs.config import ModelConfig
from jaxgest.zeggs.generator import Generator
from jaxgest.zeggs.speech_encoder import SpeechEncoder
from jaxgest.zeggs.style_encoder import StyleEncoder, sample_style


class ZeggsModel(nn.Module):
    """Speech encoder + style encoder (VAE) + generator; params ``{speech_encoder, style_encoder, generator}``.

    References: Ghorbani et al. 2023, §3 (Fig. 2).
    """

    cfg: ModelConfig

    def setup(self):
        self.speech_encoder = SpeechEncoder(self.cfg)
        self.style_encoder = StyleEncoder(self.cfg)
        self.generator = Generator(self.cfg)

    def encode_speech(self, speech, *, deterministic: bool = True):
        """``(B, T, 81)`` -> speech embeddings ``(B, T, D_S)``."""
        return self.speech_encoder(speech, deterministic=deterministic)

    def encode_style(self, style, mask=None, *, deterministic: bool = True):
        """``(B, S, P)`` (+ mask) -> ``(mu, logvar)`` each ``(B, D_e)``."""
        return self.style_encoder(style, mask, deterministic=deterministic)

    def generate(self, speech_embedding, style_embedding, pose0, root_position0, root_rotation0, facing,
                 pose_mean=None, pose_std=None):
        """Run the generator (see :class:`jaxgest.zeggs.generator.Generator`)."""
        return self.generator(pose0, root_position0, root_rotation0, facing, speech_embedding, style_embedding,
                              pose_mean, pose_std)

    def __call__(self, speech, style, style_mask, pose0, root_position0, root_rotation0, facing, sample_key,
                 pose_mean=None, pose_std=None, *, temperature: float = 1.0, deterministic: bool = True):
        """Everything: ``(output dict of the generator, aux)`` with aux = mu, logvar, style/speech embeddings."""
        s = self.encode_speech(speech, deterministic=deterministic)
        mu, logvar = self.encode_style(style, style_mask, deterministic=deterministic)
        e = sample_style(mu, logvar, sample_key, temperature)
        out = self.generate(s, e, pose0, root_position0, root_rotation0, facing, pose_mean, pose_std)
        return out, {"mu": mu, "logvar": logvar, "style_embedding": e, "speech_embedding": s}


def dummy_inputs(cfg: ModelConfig, batch: int = 1, frames: int = 4, style_frames: Optional[int] = None):
    """Zero arrays of the model's input shapes (for ``init`` / ``eval_shape``)."""
    S = style_frames or max(frames, cfg.style_min_frames)
    q = np.zeros((batch, 4), np.float32)
    q[:, 0] = 1.0
    return (jnp.zeros((batch, frames, cfg.speech_dim)), jnp.zeros((batch, S, cfg.pose_dim)),
            jnp.ones((batch, S), bool), jnp.zeros((batch, cfg.pose_dim)), jnp.zeros((batch, 3)), jnp.asarray(q),
            jnp.zeros((batch, 3)).at[:, 2].set(1.0))


def _init(cfg: ModelConfig, key: jax.Array):
    k_init, k_sample = jax.random.split(key)
    return ZeggsModel(cfg).init({"params": k_init}, *dummy_inputs(cfg), k_sample)["params"]


_init_jit = jax.jit(_init, static_argnums=0)  # jit's own cache: one compilation per model config


def init_params(cfg: ModelConfig, key: jax.Array):
    """Freshly initialised parameters ``{"speech_encoder", "style_encoder", "generator"}``.

    Called eagerly, one jitted function with the config static (``jax.jit``'s cache: repeated calls with the
    same config compile once). Under a trace (``jit``, ``eval_shape``) it is traced inline.
    """
    if isinstance(key, jax.core.Tracer):
        return _init(cfg, key)
    return _init_jit(cfg, key)


def param_shapes(cfg: ModelConfig):
    """``jax.ShapeDtypeStruct`` tree of :func:`init_params` (nothing allocated)."""
    return jax.eval_shape(functools.partial(init_params, cfg), jax.random.key(0))


def apply_fns(cfg: ModelConfig, compiler_options: Optional[dict] = None) -> dict:
    """Jitted ``encode_style(params, style, mask)``, ``encode_speech(params, speech)`` and
    ``generate(params, s_emb, e, y0, r0, q0, facing, mean, std)`` of a model config (inference, dropout off).
    Each call builds new jitted functions: keep the dict to reuse their compilations."""
    model = ZeggsModel(cfg)
    return {
        "encode_style": jax.jit(lambda p, s, m: model.apply({"params": p}, s, m, method=ZeggsModel.encode_style),
                                compiler_options=compiler_options),
        "encode_speech": jax.jit(lambda p, s: model.apply({"params": p}, s, method=ZeggsModel.encode_speech),
                                 compiler_options=compiler_options),
        "generate": jax.jit(lambda p, s, e, y0, r0, q0, f, mean, std: model.apply(
            {"params": p}, s, e, y0, r0, q0, f, mean, std, method=ZeggsModel.generate),
            compiler_options=compiler_options),
    }


def calibrate(cfg, params: dict, speech: jax.Array, style: jax.Array, pose0: jax.Array,
              root_position0: jax.Array, root_rotation0: jax.Array, facing: jax.Array, pose_mean=None,
              pose_std=None) -> dict:
    """Mean input ``(in,)`` of every layer of the recurrent decoder over a float32 generator run (the
    arguments of ``ZeggsModel.generate``; all frames and batch rows), for :func:`jaxgest.zeggs.quant.quantize_params`."""
    params = params if "generator" in params else {"generator": params}

    def run(p, *args):
        _, state = ZeggsModel(cfg).apply({"params": p}, *args, method=ZeggsModel.generate,
                                         mutable=["calibration"])
        return state["calibration"]["generator"]["decoder"]

    sown = jax.jit(run)(params, speech, style, pose0, root_position0, root_rotation0, facing, pose_mean,
                        pose_std)

    def means(tree):
        if "input_mean" in tree:
            return np.mean(np.asarray(tree["input_mean"][0], np.float64), axis=0)
        return {k: means(v) for k, v in tree.items()}

    return means(sown)

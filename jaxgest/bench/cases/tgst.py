"""TGST transfer cases: full transfer (jit / eager / NumPy), per-pose cost vs clip length, stages.

The full transfer is ``jaxgest.tgst.model.transfer_arrays`` (encode both clips, tokens, transformer,
soft swap, cross-fade, both decoders) with the ``paper`` preset's random weights -- speed does not depend
on the weight values. Inputs are exp-map-sized random clips.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.bench import numpy_tgst
from jaxgest.bench.harness import Case, Impl
from jaxgest.tgst import model as M
from jaxgest.tgst.config import preset

STYLE_FRAMES = 1280


CFG = preset("paper").model


@functools.lru_cache(maxsize=None)
def _params():
    """The paper preset's parameters (random init, seed 0), built on first use."""
    return jax.jit(lambda k: M.init_params(CFG, k))(jax.random.key(0))


def _clips(batch, frames, style_frames=STYLE_FRAMES):
    rng = np.random.default_rng(batch * 100003 + frames)
    c = jnp.asarray(rng.normal(scale=0.4, size=(batch, frames, 39)), jnp.float32)
    s = jnp.asarray(rng.normal(scale=0.4, size=(batch, style_frames, 39)), jnp.float32)
    return c, s


def _transfer_fn(cfg):
    def f(params, content, style):
        upper, lower, _ = M.transfer_arrays(params, content, style, cfg=cfg, method="soft")
        return upper, lower

    return f


def _eager(f):
    def run(*args):
        with jax.disable_jit():
            return f(*args)

    return run


def transfer_case(batch, frames, *, with_eager=True, with_numpy=True, group="", quick=True, name=None):
    f = _transfer_fn(CFG)
    impls = [Impl("jit", jax.jit(f), kind="jit")]
    if with_eager:
        impls.append(Impl("eager", _eager(f)))
    if with_numpy:
        impls.append(Impl("numpy", lambda p, c, s: numpy_tgst.transfer(p, np.asarray(c), np.asarray(s))))
    return Case(
        name=name or f"tgst_transfer_b{batch}",
        batch=batch,
        frames=frames,
        impls=impls,
        make_args=lambda: (_params(),) + _clips(batch, frames),
        rtol=1e-3,
        atol=1e-3,
        group=group,
        quick=quick,
        note=f"content {frames} + style {STYLE_FRAMES} frames; per pose = per content frame",
    )


def stage_cases(batch=8, frames=1280):
    """Autoencoder encode, transformer + swap, decoders: where the time goes."""
    cfg = CFG
    w, h = cfg.token_width, cfg.token_stride

    def encode_both(p, c, s):
        return M.encode(p["autoencoder"], c, cfg=cfg), M.encode(p["autoencoder"], s, cfg=cfg)

    def transformer_swap(p, zc, zs):
        return M.transfer_latents(p["transformer"], zc, zs, cfg=cfg, method="soft")[0]

    def decode_both(p, z):
        return M.decode(p["autoencoder"], z, cfg=cfg)

    @functools.lru_cache(maxsize=None)
    def latents():
        p = _params()
        zc, zs = jax.jit(encode_both)(p, *_clips(batch, frames))
        return zc, zs, jax.jit(transformer_swap)(p, zc, zs)

    return [
        Case("tgst_stage_encode_both", batch, frames, [Impl("jit", jax.jit(encode_both), kind="jit")],
             make_args=lambda: (_params(),) + _clips(batch, frames), group="stages"),
        Case("tgst_stage_transformer_swap", batch, frames, [Impl("jit", jax.jit(transformer_swap), kind="jit")],
             make_args=lambda: (_params(),) + latents()[:2], group="stages",
             note=f"tokens (w={w}, h={h}), T_E x2, T_D, soft swap, cross-fade"),
        Case("tgst_stage_decode_both", batch, frames, [Impl("jit", jax.jit(decode_both), kind="jit")],
             make_args=lambda: (_params(), latents()[2]), group="stages"),
    ]


def cases(quick: bool) -> list:
    out = [transfer_case(1, 1280, with_eager=True), transfer_case(8, 1280, with_eager=True)]
    lengths = (1280, 5120, 20480) if quick else (320, 640, 1280, 2560, 5120, 10240, 20480)
    for n in lengths:
        out.append(transfer_case(1, n, with_eager=False, with_numpy=False, group="tgst_scaling",
                                 name=f"tgst_scaling_{n}"))
    out.extend(stage_cases())
    return out

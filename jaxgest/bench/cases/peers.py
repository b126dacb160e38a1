"""Side by side with eager PyTorch (``pip install ".[bench]"``): TGST transfer and ZeroEGGS generation.

Every case here is timed in interleaved rounds (``jit``, ``torch``, ``jit``, ``torch``, ...; median of the
rounds) after the equality check (``torch_compile``: :mod:`jaxgest.bench.torch_peers.compiled`, its compile
time reported as ``compile_s``, checked against the eager peer ``torch``), with ``torch.set_num_threads(cores)`` and XLA's CPU client on the same
cores (its intra-op pool uses every core of the process). Without torch the cases run without their
``torch`` implementation (``python -m benchmarks`` says so in one line).

* ``peer_tgst_transfer_b{1,8}``: the full transfer (content 1280 + style 1280 frames, both padded by the
  16 edge frames), ``transformer.variant="authors"`` (post-LN, one shared LayerNorm per block: the network
  of the authors' code, which :class:`jaxgest.bench.torch_peers.TGSTPeer` ports), random weights (seed 0),
  ``jit`` = :func:`jaxgest.tgst.model.transfer_arrays` vs ``torch``.
* ``peer_zeggs_generate_b{1,32}``: the generator (paper preset, random LeCun-normal weights) over 300
  generated frames (60 in ``--quick``): ``jit`` (the model, fp32), ``bf16`` and ``int8``
  (:mod:`jaxgest.zeggs.quant`, checked with a loose tolerance: ``max_abs_diff`` is their deviation from
  fp32 after all frames) vs ``torch`` (the official generator, fp32).

Work per call (for the floor fraction): TGST counts the matmul / conv FLOPs of the network
(:func:`tgst_flops`; bytes = clips in + poses out, it is compute-bound); ZeroEGGS counts 2 FLOPs per
decoder weight and batch row per frame, and bytes = the decoder's weights in the implementation's format
per frame (75.7 MB fp32 do not stay in any cache between frames).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import os

import jax
import numpy as np

from jaxgest.bench.cases import tgst as T
from jaxgest.bench.cases import zeggs as Z
from jaxgest.bench.harness import Case, Impl
from jaxgest.tgst import model as M
from jaxgest.tgst.config import preset as tgst_config
from jaxgest.zeggs import quant as Q
from jaxgest.zeggs.model import calibrate
from jaxgest.zeggs.generator import input_scale

STYLE_FRAMES = 1280


def torch_available() -> bool:
    return importlib.util.find_spec("torch") is not None


def threads() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def torch_threads() -> list:
    """The torch configurations timed: ``torch`` = as many intra-op threads as XLA uses (every core of the
    process), ``torch_1t`` = one thread. On a loaded machine torch's OpenMP pool can be many times slower
    with 2 threads than with 1 (a thread waits at each op's barrier for a descheduled partner), so both are
    timed and the speed-up is stated against the faster of the two (never against a slowed-down peer)."""
    n = threads()
    return [("torch", n)] + ([("torch_1t", 1)] if n > 1 else [])


def compile_modes() -> list:
    """The ``torch.compile`` modes timed: ``default``, plus ``max-autotune-no-cudagraphs`` when
    ``JAXGEST_BENCH_MAX_AUTOTUNE=1`` (it autotunes GEMM templates at compile time: minutes per case on a
    2-core CPU)."""
    return ["default"] + (["max-autotune-no-cudagraphs"] if os.environ.get("JAXGEST_BENCH_MAX_AUTOTUNE") == "1"
                          else [])


def compiled_impls(build) -> list:
    """``torch_compile`` (and ``torch_compile_max``) impls: ``build(mode)`` -> the compiled peer's call, built
    at the first call with every core's threads (Inductor compiles the thread count into its kernels, so
    one thread setting per compiled peer); the first call (trace + compile + one run) is ``compile_s``;
    checked against the eager peer (``torch``)."""
    out = []
    for mode in compile_modes():
        holder = {}

        def fn(*args, _mode=mode, _holder=holder):
            from jaxgest.bench import torch_peers as P

            P.set_threads(threads())
            if "f" not in _holder:
                _holder["f"] = build(_mode)
            return _holder["f"](*args)

        name = "torch_compile" if mode == "default" else "torch_compile_max"
        out.append(Impl(name, fn, kind="compiled", reference="torch"))
    return out


def authors_config():
    """The paper preset with the authors' transformer (post-LN, one LayerNorm per block)."""
    cfg = tgst_config("paper").model
    return dataclasses.replace(cfg, transformer=dataclasses.replace(cfg.transformer, variant="authors",
                                                                    layernorms_per_block=1))


TCFG = authors_config()


@functools.lru_cache(maxsize=None)
def tgst_params():
    return jax.jit(lambda k: M.init_params(TCFG, k))(jax.random.key(0))


def tgst_flops(cfg, batch: int, content_frames: int, style_frames: int) -> float:
    """Matmul / conv FLOPs (2 per multiply-add) of one transfer (banded attention: the band only)."""
    a, t = cfg.autoencoder, cfg.transformer
    red, d, om = a.time_reduction, t.token_dim, t.omega

    def padded(f):
        return M.edge_layout(f, cfg=cfg)[1]

    def encode(L):
        c = (a.upper_channels,) + tuple(a.encoder_channels)
        n, total = L, 0.0
        for cin, cout, k, s in zip(c[:-1], c[1:], a.encoder_kernels, a.encoder_strides):
            n = -(-n // s)
            total += 2.0 * n * cin * cout * k
        return total

    def decode(T_):
        total = 0.0
        for hidden, out in ((a.upper_decoder_channels, a.upper_channels), (a.lower_decoder_channels,
                                                                          a.lower_channels)):
            c = (a.latent_dim,) + tuple(hidden) + (out,)
            n = T_
            for cin, cout, k, up in zip(c[:-1], c[1:], a.decoder_kernels, a.decoder_upsample):
                n *= up
                total += 2.0 * n * cin * cout * k
        return total

    Lc, Ls = padded(content_frames), padded(style_frames)
    Tc, Ts = Lc // red, -(-style_frames // red)
    Nc, Ns = Tc // cfg.token_stride - 1, Ts // cfg.token_stride - 1
    enc_tokens = (Nc + 1) + (Ns + 1)
    transformer = enc_tokens * (12 * d * d + 4 * d * (2 * om + 1))  # qkv, out, mlp; banded scores + mix
    transformer += 2 * d * d * (3 * Nc + 2 * Ns) + 4 * d * Nc * Ns  # decoder: q, out, mlp; kv; attention
    transformer += 4 * d * Nc * Ns  # soft swap: similarities + blend
    return batch * (encode(Lc) + encode(Ls) + transformer + decode(Tc))


def tgst_case(batch: int, frames: int = 1280, *, with_torch: bool = True, repeats_note: str = "") -> Case:
    cfg = TCFG

    def f(params, content, style):
        upper, lower, _ = M.transfer_arrays(params, content, style, cfg=cfg, method="soft")
        return upper, lower

    impls = [Impl("jit", jax.jit(f), kind="jit")]
    if with_torch:
        from jaxgest.bench import torch_peers as P

        peer = {}

        def make(n):
            def torch_fn(params, content, style):
                P.set_threads(n)
                if "f" not in peer:
                    peer["f"] = P.tgst_call(P.load_tgst(cfg, params))
                return peer["f"](params, content, style)
            return torch_fn

        impls += [Impl(name, make(n)) for name, n in torch_threads()]
        impls += compiled_impls(lambda mode: P.compiled.tgst_compiled_call(P.load_tgst(cfg, tgst_params()), mode))
    nbytes = 4.0 * batch * (frames * (cfg.autoencoder.upper_channels * 2 + cfg.autoencoder.lower_channels)
                            + STYLE_FRAMES * cfg.autoencoder.upper_channels)
    flops = tgst_flops(cfg, batch, frames, STYLE_FRAMES)
    return Case(
        name=f"peer_tgst_transfer_b{batch}", batch=batch, frames=frames, impls=impls,
        make_args=lambda: (tgst_params(),) + T._clips(batch, frames), rtol=1e-3, atol=1e-3,
        interleave=True, work=lambda impl: (flops, nbytes),
        note=f"authors' network (variant=authors); content {frames} + style {STYLE_FRAMES} frames; "
             f"torch threads {threads()} (torch) and 1 (torch_1t)",
    )


CALIBRATION_SEED, CALIBRATION_FRAMES = 1, 200  # the bias correction's calibration run (other inputs)


@functools.lru_cache(maxsize=None)
def _calibration():
    return calibrate(Z.CFG, Z._params(), *Z.generator_inputs(Z.CFG, 1, CALIBRATION_FRAMES,
                                                                seed=CALIBRATION_SEED))


@functools.lru_cache(maxsize=None)
def _quantized(fmt: str, corrected: bool = True):
    return Q.quantize_params(Z._params(), fmt, input_means=_calibration() if corrected else None)


def _format_fn(fmt: str):
    gen = jax.jit(Z._generate_fn(Z.CFG))  # the model itself, on params whose decoder kernels are in ``fmt``

    def run(params, speech, style, pose0, root_position0, root_rotation0, facing):
        qp = _quantized(fmt) if params is Z._params() else Q.quantize_params(params, fmt)
        return gen(qp, speech, style, pose0, root_position0, root_rotation0, facing)

    return run


@functools.lru_cache(maxsize=None)
def decoder_counts() -> tuple[int, int]:
    """(kernel weights, biases) of the generator's decoder (per-frame parameters)."""
    leaves = jax.tree_util.tree_flatten_with_path(Z._params()["generator"]["decoder"])[0]
    count = lambda key: sum(int(np.prod(x.shape)) for p, x in leaves if key in jax.tree_util.keystr(p))  # noqa
    return count("kernel"), count("bias")


FORMAT_ATOL = 0.5  # loose check of bf16 / int8 against fp32 (normalised pose units after all frames)


def zeggs_case(batch: int, frames: int, *, with_torch: bool = True, formats=("bf16", "int8")) -> Case:
    cfg = Z.CFG
    impls = [Impl("jit", jax.jit(Z._generate_fn(cfg)), kind="jit")]
    for fmt in formats:
        impls.append(Impl(fmt, _format_fn(fmt), atol=FORMAT_ATOL, rtol=0.0))
    if with_torch:
        from jaxgest.bench import torch_peers as P

        P_ = cfg.pose_dim
        scale = np.asarray(input_scale(cfg, np.zeros(P_, np.float32), np.ones(P_, np.float32)))
        peer = {}

        def make(n):
            def torch_fn(params, *inputs):
                P.set_threads(n)
                if "f" not in peer:
                    peer["f"] = P.zeggs_call(P.load_zeggs(cfg, params), scale)
                return peer["f"](params, *inputs)
            return torch_fn

        impls += [Impl(name, make(n)) for name, n in torch_threads()]
        impls += compiled_impls(lambda mode: P.compiled.zeggs_compiled_call(P.load_zeggs(cfg, Z._params()), scale,
                                                                            mode))
    per_weight = {"bf16": 2.0, "int8": 1.125}  # int8: one float32 scale per 32 weights

    def work(impl):
        n_weights, n_bias = decoder_counts()
        flops = 2.0 * batch * n_weights * frames
        w = per_weight.get(impl, 4.0)
        nbytes = frames * (n_weights * w + 4.0 * n_bias)
        return flops, nbytes

    return Case(
        name=f"peer_zeggs_generate_b{batch}", batch=batch, frames=frames, impls=impls,
        make_args=lambda: (Z._params(),) + Z.generator_inputs(cfg, batch, frames), rtol=1e-3, atol=1e-3,
        interleave=True, work=work,
        note=f"paper preset generator, random weights; {frames} generated frames; bf16/int8: "
             f"jaxgest.zeggs.quant (max_abs_diff = deviation from fp32); torch threads {threads()}",
    )


def format_accuracy(frames: int = 600, batch: int = 1, seed: int = 0) -> dict:
    """RMS pose difference of each weight format against fp32 after ``frames`` generated frames (bias
    correction calibrated on ``CALIBRATION_FRAMES`` frames of other inputs; also without it).

    ``{fmt: {"rms": ..., "rms_pct_of_range": ..., "max_abs": ...}}``; the pose range is the mean over
    channels of (max - min over the fp32 frames), normalised pose units. ``control`` is fp32 again with
    the initial pose moved by 1e-6 (how much an ulp-sized change grows over the frames).
    """
    cfg = Z.CFG
    args = Z.generator_inputs(cfg, batch, frames, seed=seed)
    gen = jax.jit(Z._generate_fn(cfg))
    ref = np.asarray(gen(Z._params(), *args)["pose"], np.float64)
    rng = np.mean(ref.max(axis=1) - ref.min(axis=1))
    out = {}

    def stats(y):
        d = np.asarray(y, np.float64) - ref
        rms = float(np.sqrt(np.mean(d[:, -1] ** 2)))  # the last frame
        rms_all = float(np.sqrt(np.mean(d ** 2)))
        return {"rms_last_frame": rms, "rms_all_frames": rms_all,
                "rms_pct_of_range": 100.0 * rms_all / float(rng), "max_abs": float(np.max(np.abs(d)))}

    for fmt in Q.WEIGHT_FORMATS[1:]:
        out[fmt] = stats(gen(_quantized(fmt), *args)["pose"])
        out[f"{fmt}_without_bias_correction"] = stats(gen(_quantized(fmt, False), *args)["pose"])
    moved = (args[0], args[1], args[2] + 1e-6) + tuple(args[3:])
    out["control_fp32_pose0_plus_1e-6"] = stats(gen(Z._params(), *moved)["pose"])
    out["pose_range"] = float(rng)
    out["frames"] = frames
    return out


def cases(quick: bool) -> list:
    with_torch = torch_available()
    frames = 60 if quick else 300
    return [
        tgst_case(1, with_torch=with_torch),
        tgst_case(8, with_torch=with_torch),
        zeggs_case(1, frames, with_torch=with_torch),
        zeggs_case(32, frames if not quick else 30, with_torch=with_torch),
    ]

"""Harness demonstration: a 1D-conv stack of the TGST encoder's shape, jit vs eager JAX vs NumPy.

NOT a model benchmark. It exists so the suite runs end to end and its numbers can be read without any
model code: three convolutions over time, 39 -> 64 (kernel 1, stride 1) -> 32 (kernel 3, stride 2) -> 16
(kernel 3, stride 2), PyTorch-style padding ``kernel // 2``, leaky ReLU (0.2) between them -- the widths,
kernels and strides of the TGST autoencoder's encoder (``jaxgest.tgst.config``, Kuriyama et al. 2022,
App. A) with fixed random weights, written inline. The JAX version uses ``lax.conv_general_dilated``; the
NumPy version is an independent im2col + matmul, so the equality check compares two algorithms.

Cases: ``toy_conv_b1`` and ``toy_conv_b8`` (1280 frames, jit / eager / numpy) and the family
``toy_conv_scaling_<frames>`` (batch 1, 320 .. 20480 frames, group ``toy_conv_scaling``) for the
per-pose-cost-vs-clip-length plot.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.harness import Case, Impl

CHANNELS = (39, 64, 32, 16)
KERNELS = (1, 3, 3)
STRIDES = (1, 2, 2)
SLOPE = 0.2
NOTE = "harness demonstration (inline conv stack 39->64->32->16), not a model"


def init_params(seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Fixed random weights: per layer a kernel (k, c_in, c_out) and a bias (c_out,), float32."""
    rng = np.random.default_rng(seed)
    params = []
    for c_in, c_out, k in zip(CHANNELS[:-1], CHANNELS[1:], KERNELS):
        w = rng.normal(scale=1.0 / np.sqrt(c_in * k), size=(k, c_in, c_out)).astype(np.float32)
        b = rng.normal(scale=0.1, size=(c_out,)).astype(np.float32)
        params.append((w, b))
    return params


def conv_stack(params, x: jax.Array) -> jax.Array:
    """(batch, frames, 39) -> (batch, ceil(frames / 4), 16) with ``lax.conv_general_dilated``."""
    h = x
    for i, ((w, b), k, s) in enumerate(zip(params, KERNELS, STRIDES)):
        h = jax.lax.conv_general_dilated(h, w, window_strides=(s,), padding=[(k // 2, k // 2)],
                                         dimension_numbers=("NWC", "WIO", "NWC")) + b[None, None, :]
        if i < len(params) - 1:
            h = jax.nn.leaky_relu(h, SLOPE)
    return h


def conv_stack_numpy(params, x: np.ndarray) -> np.ndarray:
    """The same stack in NumPy: explicit padding, im2col windows, one matrix product per layer."""
    h = np.asarray(x, np.float32)
    for i, ((w, b), k, s) in enumerate(zip(params, KERNELS, STRIDES)):
        w, b = np.asarray(w), np.asarray(b)
        hp = np.pad(h, ((0, 0), (k // 2, k // 2), (0, 0)))
        cols = np.lib.stride_tricks.sliding_window_view(hp, k, axis=1)[:, ::s]  # (B, F_out, C_in, k)
        batch, f_out = cols.shape[:2]
        # One 2-D GEMM per layer (NumPy's stacked 3-D matmul does not reach BLAS and is ~8x slower).
        cols = cols.transpose(0, 1, 3, 2).reshape(batch * f_out, k * w.shape[1])
        h = (cols @ w.reshape(k * w.shape[1], w.shape[2]) + b).reshape(batch, f_out, w.shape[2])
        if i < len(params) - 1:
            h = np.where(h >= 0, h, SLOPE * h)
    return h


def _eager(*args):
    with jax.disable_jit():
        return conv_stack(*args)


def _numpy(params, x):
    return conv_stack_numpy(params, np.asarray(x))


def toy_case(batch: int, frames: int, *, name: str, group: str = "", quick: bool = True) -> Case:
    def make_args():
        x = np.random.default_rng(batch * 7919 + frames).normal(size=(batch, frames, CHANNELS[0]))
        params = jax.tree_util.tree_map(jnp.asarray, init_params())
        return params, jnp.asarray(x, jnp.float32)

    return Case(
        name=name,
        batch=batch,
        frames=frames,
        impls=[Impl("jit", jax.jit(conv_stack), kind="jit"), Impl("eager", _eager), Impl("numpy", _numpy)],
        make_args=make_args,
        rtol=1e-4,
        atol=1e-4,
        group=group,
        quick=quick,
        note=NOTE,
    )


def cases(quick: bool) -> list[Case]:
    out = [toy_case(1, 1280, name="toy_conv_b1"), toy_case(8, 1280, name="toy_conv_b8")]
    lengths = (320, 1280, 5120, 20480) if quick else (320, 640, 1280, 2560, 5120, 10240, 20480)
    out += [toy_case(1, n, name=f"toy_conv_scaling_{n}", group="toy_conv_scaling") for n in lengths]
    return out

"""Weight formats of the ZeroEGGS generator: ``fp32`` | ``bf16`` | ``int8`` (inference only).

At batch 1 the generator is bound by memory bandwidth: every frame streams the decoder's kernels (input
layer, two GRU layers, output layer; 75.7 MB in float32 with the paper preset) through a handful of
matrix-vector products. Narrower weights stream fewer bytes:

* ``fp32``: the trained weights (the model itself);
* ``bf16``: every decoder kernel rounded to bfloat16 (2 bytes per weight);
* ``int8``: weight-only symmetric quantisation with one float32 scale per output channel (column of the
  ``(in, out)`` kernel): ``w ~ q * scale``, ``q = round(w / scale)`` in [-127, 127], ``scale =
  max|w_col| / 127`` (1 byte per weight). Activations stay float32.

:func:`qdense` dequantises in the matmul: ``bf16`` is a native bf16 x bf16 -> f32 ``dot``; ``int8`` a
``dot`` on ``q.astype(float32)`` times the scales. Measured on XLA CPU (jaxlib 0.10.2, 2 cores): inside
the generator's scan XLA hoists the (loop-invariant) conversion out of the loop, so both formats stream
float32 weights and run at fp32 speed at batch 1; written as a fused multiply + reduce
(``sum_k x[b, k] * float(q[k, n])``, which could stream the narrow weights) one 1262 x 4096 product takes
~200-400 ms instead of ~1 ms, and a per-call conversion costs 3x the float32 dot -- XLA CPU has no
fast mixed-precision matrix-vector kernel, so on this backend the formats trade accuracy for memory, not
for batch-1 speed (the benchmark suite's ``peer_zeggs_*`` cases time them).

The hidden-state initializer (run once per sequence) and the biases stay float32. Accuracy: the pose
difference after 600 generated frames against ``fp32`` is measured by the benchmark suite
(``benchmarks/cases/peers.py``) and reported in the README.

:func:`make_generate` returns ``generate(qparams, speech, style, pose0, root_position0, root_rotation0,
facing, pose_mean, pose_std)`` with the same inputs and output dict as ``ZeggsModel.generate``;
:func:`quantize_params` converts the model's ``params`` (only ``params["generator"]`` is used).

References: Ghorbani et al. 2023, §3.3 (the generator); Jacob et al. 2018 (per-channel weight-only
quantisation).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from jaxgest.zeggs.config import ModelConfig
from jaxgest.zeggs.generator import (HiddenStateInitializer, _prepare, _stack_outputs, local_facing,
                                     update_character_state)

WEIGHT_FORMATS = ("fp32", "bf16", "int8")


def check_format(weight_format: str) -> str:
    if weight_format not in WEIGHT_FORMATS:
        raise ValueError(f"weight format must be one of {'|'.join(WEIGHT_FORMATS)}, got {weight_format!r}")
    return weight_format


def quantize_kernel(kernel: jax.Array, weight_format: str) -> dict:
    """``(in, out)`` float32 kernel -> ``{"w": kernel in the format, "scale": (out,) float32 or None}``."""
    check_format(weight_format)
    kernel = jnp.asarray(kernel, jnp.float32)
    if weight_format == "fp32":
        return {"w": kernel, "scale": None}
    if weight_format == "bf16":
        return {"w": kernel.astype(jnp.bfloat16), "scale": None}
    amax = jnp.max(jnp.abs(kernel), axis=0)
    scale = jnp.where(amax > 0, amax / 127.0, 1.0)
    q = jnp.clip(jnp.round(kernel / scale[None]), -127, 127).astype(jnp.int8)
    return {"w": q, "scale": scale}


def dequantize(qk: dict) -> jax.Array:
    """The float32 kernel a quantised kernel stands for."""
    w = qk["w"].astype(jnp.float32)
    return w if qk["scale"] is None else w * qk["scale"][None]


def qdense(x: jax.Array, qk: dict, bias: jax.Array) -> jax.Array:
    """``x (b, in) @ kernel + bias`` with the kernel in its stored format, accumulated in float32."""
    w, scale = qk["w"], qk["scale"]
    if w.dtype == jnp.float32:
        y = x @ w
    elif w.dtype == jnp.bfloat16:
        y = jnp.dot(x.astype(jnp.bfloat16), w, preferred_element_type=jnp.float32)
    else:
        y = x @ w.astype(jnp.float32)
    if scale is not None:
        y = y * scale[None]
    return y + bias[None]


def quantize_params(params: dict, weight_format: str) -> dict:
    """The generator's parameters with every decoder kernel in ``weight_format``.

    Returns ``{"initializer": float32 params, "decoder": {layer: {"kernel": {"w", "scale"}, "bias"}}}``.
    """
    check_format(weight_format)
    g = params["generator"] if "generator" in params else params

    def convert(tree):
        if isinstance(tree, Mapping) and "kernel" in tree:
            return {"kernel": quantize_kernel(tree["kernel"], weight_format), "bias": jnp.asarray(tree["bias"])}
        return {k: convert(v) for k, v in tree.items()}

    return {"initializer": g["initializer"], "decoder": convert(dict(g["decoder"]))}


def _gru(qp: dict, h: jax.Array, x: jax.Array) -> jax.Array:
    """PyTorch GRU gates (r, z, n), as :class:`jaxgest.zeggs.generator.GRULayer`."""
    H = h.shape[-1]
    gi = qdense(x, qp["input"]["kernel"], qp["input"]["bias"])
    gh = qdense(h, qp["hidden"]["kernel"], qp["hidden"]["bias"])
    r = jax.nn.sigmoid(gi[:, :H] + gh[:, :H])
    z = jax.nn.sigmoid(gi[:, H:2 * H] + gh[:, H:2 * H])
    n = jnp.tanh(gi[:, 2 * H:] + r * gh[:, 2 * H:])
    return (1.0 - z) * n + z * h


def make_generate(cfg: ModelConfig):
    """``generate(qparams, speech_embedding, style, pose0, root_position0, root_rotation0, facing,
    pose_mean=None, pose_std=None) -> {"pose", "root_position", "root_rotation"}`` on quantised params.

    The same computation as :class:`jaxgest.zeggs.generator.Generator` (and, with ``fp32``, the same
    numbers up to float reassociation).
    """

    def generate(qparams: dict, speech: jax.Array, style: jax.Array, pose0: jax.Array,
                 root_position0: jax.Array, root_rotation0: jax.Array, facing: jax.Array,
                 pose_mean=None, pose_std=None) -> dict[str, Any]:
        style, consts = _prepare(cfg, pose0, root_position0, root_rotation0, facing, speech, style,
                                 pose_mean, pose_std)
        facing_, mean, std, in_scale = consts
        hidden = HiddenStateInitializer(cfg).apply({"params": qparams["initializer"]}, pose0 * in_scale[None],
                                                   local_facing(facing_, root_rotation0), style[:, 0])
        dec = qparams["decoder"]

        def step(carry, inp):
            hid, pose, pos, rot = carry
            d = dec
            speech_t, style_t = inp
            x = jnp.concatenate([pose * in_scale[None], local_facing(facing_, rot), speech_t, style_t], axis=-1)
            h = jax.nn.elu(qdense(x, d["input_layer"]["kernel"], d["input_layer"]["bias"]))
            h = jnp.concatenate([h, x], axis=-1)
            new_hidden = []
            for i in range(cfg.gru_layers):
                h = _gru(d[f"gru{i}"], hid[i], h)
                new_hidden.append(h)
            y = qdense(h, d["output_layer"]["kernel"], d["output_layer"]["bias"])
            pos, rot = update_character_state(y, pos, rot, cfg=cfg, pose_mean=mean, pose_std=std)
            return (tuple(new_hidden), y, pos, rot), (y, pos, rot)

        xs = (jnp.moveaxis(speech[:, 1:], 1, 0), jnp.moveaxis(style[:, 1:], 1, 0))
        carry = (tuple(hidden), pose0, root_position0, root_rotation0)
        _, (ys, ps, qs) = jax.lax.scan(step, carry, xs)
        return _stack_outputs(pose0, root_position0, root_rotation0, *(jnp.moveaxis(a, 0, 1) for a in (ys, ps, qs)))

    return generate


def weight_bytes(qparams: dict) -> int:
    """Bytes of the decoder's parameters (what one generated frame streams at batch 1)."""
    return int(sum(leaf.size * leaf.dtype.itemsize for leaf in jax.tree_util.tree_leaves(qparams["decoder"])))

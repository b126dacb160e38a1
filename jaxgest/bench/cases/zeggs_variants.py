"""Benchmark-local variants of the ZeroEGGS generator (optimisation experiments; the model is unchanged).

Each variant is a functional re-implementation of ``ZeggsModel.generate`` on the *same* flax parameters
(``params["generator"]``), checked against the model's own ``jit`` before it is timed:

* ``func``: the same computation written with ``lax.scan`` directly (sanity: should time like ``jit``);
* ``hoist``: the speech and style columns of the two matrices that read the per-frame input (the input
  layer, rows 1134..1262 of 1262, and GRU 0's input matrix, the same rows of its ``x`` part) are applied to
  the whole sequence in one GEMM before the scan -- they do not depend on the recurrence;
* ``fused``: ``hoist`` + the remaining per-frame input ``[pose, facing]`` is multiplied once by the
  concatenated ``[input layer | GRU 0 input (x rows)]`` kernel (one dot of 1134 x 4096 instead of two);
* ``unroll<k>``: ``fused`` with ``lax.scan(..., unroll=k)``;
* ``bf16``: ``fused`` with bfloat16 kernels (half the weight bytes streamed per frame; the dot accumulates
  in float32, ``preferred_element_type``); its own case (``zeggs_variant_bf16_*``) with a loose tolerance,
  ``max_abs_diff`` in the record is the accuracy cost after ``frames`` autoregressive frames.

Cases ``zeggs_variants_b{1,32}`` (impls ``jit`` = the model, then ``hoist``, ``fused``, ``unroll4``; the
others are equality-tested in ``tests/integration/test_bench_harness.py`` but not timed by the suite) and
``zeggs_variant_bf16_b{1,32}``; not part of ``--quick``. 150 generated frames at batch 1, 60 at batch 32.

Measured (jaxlib 0.10.2, AMD EPYC Zen 5, one XLA thread, process CPU time per frame, machine load ~8):
the generator is bound by its six matrix products (a loop of those dots alone costs 95-100 % of a
frame: ~2.4 ms per frame at batch 1, ~9 ms at batch 32); no variant beats the model's own loop (batch 1:
hoist / fused / unroll 2-8 within -2 .. +11 % of its CPU time; batch 32: 6-15 % more). At batch 1 XLA
CPU turns a bf16 x bf16 -> f32 dot into an f32 dot on bf16-rounded weights (the converts are hoisted out
of the loop: the same bytes are streamed, +19 % CPU time); at batch 32 it runs a native bf16 GEMM
(YNNPACK fusion): -15 % CPU time, for an output error of ~0.9 % RMS (max |diff| ~0.013) after 300 frames.
References: Ghorbani et al. 2023, §3.3 (the generator); jaxgest.zeggs.generator (the equations).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgest.bench.cases.zeggs import CFG, _generate_fn, _params, generator_inputs
from jaxgest.bench.harness import Case, Impl
from jaxgest.zeggs.config import ModelConfig
from jaxgest.zeggs.generator import HiddenStateInitializer, local_facing, update_character_state


def _gru_gates(gi, gh, h):
    H = h.shape[-1]
    r = jax.nn.sigmoid(gi[:, :H] + gh[:, :H])
    z = jax.nn.sigmoid(gi[:, H:2 * H] + gh[:, H:2 * H])
    n = jnp.tanh(gi[:, 2 * H:] + r * gh[:, 2 * H:])
    return (1.0 - z) * n + z * h


def _dot(x, w):
    if w.dtype == x.dtype:
        return x @ w
    return jnp.dot(x.astype(w.dtype), w, preferred_element_type=jnp.float32)


def make_variant(cfg: ModelConfig, *, hoist: bool, fused: bool, unroll: int = 1, weight_dtype=jnp.float32):
    """``generate(params, speech, style, pose0, root_position0, root_rotation0, facing) -> dict``."""
    P = cfg.pose_dim
    n_pf = P + cfg.facing_dim  # per-frame inputs that depend on the recurrence: [pose, local facing]
    mean, std = jnp.zeros((P,)), jnp.ones((P,))

    def generate(params, speech, style, pose0, root_position0, root_rotation0, facing):
        g = params["generator"]
        d = g["decoder"]
        b, T, _ = speech.shape
        hidden = HiddenStateInitializer(cfg).apply({"params": g["initializer"]}, pose0,
                                                   local_facing(facing, root_rotation0), style)
        w_in, b_in = d["input_layer"]["kernel"], d["input_layer"]["bias"]
        w0i, b0i = d["gru0"]["input"]["kernel"], d["gru0"]["input"]["bias"]
        H = cfg.gru_hidden
        w0i_h, w0i_x = w0i[:H], w0i[H:]  # GRU 0 reads [elu(input layer), x]
        cast = lambda w: w.astype(weight_dtype)  # noqa: E731
        speech_seq = jnp.moveaxis(speech[:, 1:], 1, 0)  # (T-1, b, D_S)
        if hoist:
            # speech / style columns: applied to every frame at once, outside the recurrence.
            se = jnp.concatenate([speech_seq, jnp.broadcast_to(style[None], (T - 1,) + style.shape)], -1)
            pre_in = jnp.einsum("tbk,kh->tbh", se, w_in[n_pf:]) + b_in[None, None]
            pre_g0 = jnp.einsum("tbk,kh->tbh", se, w0i_x[n_pf:]) + b0i[None, None]
            xs = (pre_in, pre_g0)
            if fused:
                w_x = cast(jnp.concatenate([w_in[:n_pf], w0i_x[:n_pf]], axis=1))  # (n_pf, H + 3H)
            else:
                w_in_pf, w0_pf = cast(w_in[:n_pf]), cast(w0i_x[:n_pf])
        else:
            xs = (speech_seq,)
            w_in_full, w0x_full = cast(w_in), cast(w0i_x)
        w0i_h = cast(w0i_h)
        w0h, b0h = cast(d["gru0"]["hidden"]["kernel"]), d["gru0"]["hidden"]["bias"]
        w1i, b1i = cast(d["gru1"]["input"]["kernel"]), d["gru1"]["input"]["bias"]
        w1h, b1h = cast(d["gru1"]["hidden"]["kernel"]), d["gru1"]["hidden"]["bias"]
        wo, bo = cast(d["output_layer"]["kernel"]), d["output_layer"]["bias"]

        def step(carry, inp):
            (h0, h1), pose, pos, rot = carry
            pf = jnp.concatenate([pose, local_facing(facing, rot)], axis=-1)
            if hoist:
                pre_in, pre_g0 = inp
                if fused:
                    both = _dot(pf, w_x)
                    a_in, a_g0 = both[:, :H], both[:, H:]
                else:
                    a_in, a_g0 = _dot(pf, w_in_pf), _dot(pf, w0_pf)
                u = jax.nn.elu(a_in + pre_in)
                gi0 = _dot(u, w0i_h) + a_g0 + pre_g0
            else:
                (s_t,) = inp
                x = jnp.concatenate([pf, s_t, style], axis=-1)
                u = jax.nn.elu(_dot(x, w_in_full) + b_in[None])
                gi0 = _dot(u, w0i_h) + _dot(x, w0x_full) + b0i[None]
            h0 = _gru_gates(gi0, _dot(h0, w0h) + b0h[None], h0)
            h1 = _gru_gates(_dot(h0, w1i) + b1i[None], _dot(h1, w1h) + b1h[None], h1)
            y = _dot(h1, wo) + bo[None]
            pos, rot = update_character_state(y, pos, rot, cfg=cfg, pose_mean=mean, pose_std=std)
            return ((h0, h1), y, pos, rot), (y, pos, rot)

        carry = (tuple(hidden), pose0, root_position0, root_rotation0)
        _, (ys, ps, qs) = jax.lax.scan(step, carry, xs, unroll=unroll)
        first = lambda a0, seq: jnp.concatenate([a0[:, None], jnp.moveaxis(seq, 0, 1)], axis=1)  # noqa: E731
        return {"pose": first(pose0, ys), "root_position": first(root_position0, ps),
                "root_rotation": first(root_rotation0, qs)}

    return generate


VARIANTS = {
    "func": dict(hoist=False, fused=False),
    "hoist": dict(hoist=True, fused=False),
    "fused": dict(hoist=True, fused=True),
    "unroll2": dict(hoist=True, fused=True, unroll=2),
    "unroll4": dict(hoist=True, fused=True, unroll=4),
}


TIMED = ("hoist", "fused", "unroll4")  # timed by the suite (every variant is tested for equality)


def variants_case(batch: int, frames: int) -> Case:
    impls = [Impl("jit", jax.jit(_generate_fn(CFG)), kind="jit")]
    impls += [Impl(name, jax.jit(make_variant(CFG, **VARIANTS[name])), kind="jit") for name in TIMED]
    return Case(name=f"zeggs_variants_b{batch}", batch=batch, frames=frames, impls=impls,
                make_args=lambda: (_params(),) + generator_inputs(CFG, batch, frames), rtol=1e-3, atol=1e-3,
                quick=False, group="", note="benchmark-local generator variants (see jaxgest/bench/cases/"
                                            "zeggs_variants.py); jit = the model's generate")


def bf16_case(batch: int, frames: int) -> Case:
    impls = [Impl("jit", jax.jit(make_variant(CFG, hoist=True, fused=True)), kind="jit"),
             Impl("bf16", jax.jit(make_variant(CFG, hoist=True, fused=True, weight_dtype=jnp.bfloat16)),
                  kind="jit")]
    return Case(name=f"zeggs_variant_bf16_b{batch}", batch=batch, frames=frames, impls=impls,
                make_args=lambda: (_params(),) + generator_inputs(CFG, batch, frames), rtol=0.0, atol=1.0,
                quick=False, note="fused variant, float32 (jit) vs bfloat16 kernels; max_abs_diff = accuracy "
                                  "cost (normalised pose units, cm for root position) after all frames")


def cases(quick: bool) -> list:
    # The per-frame cost does not depend on the length (one scan): short sequences keep the compiled
    # variants (each compiled twice: equality check, then timed compile) within about a minute.
    return [variants_case(1, 150), variants_case(32, 60), bf16_case(1, 150), bf16_case(32, 60)]

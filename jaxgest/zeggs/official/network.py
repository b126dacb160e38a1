"""The ZeroEGGS authors' released networks as pure JAX functions of their own parameters.

The parameters are the authors' ``state_dict()`` arrays under their own names (``layer1.weight_ih_l0``,
``encoder.blocks.0.attention.multi_head_attention.in_proj_weight``, ...), so a released model is imported
without a mapping table and a parity test compares like with like. Convolutions take PyTorch's ``(out, in,
k)`` kernels directly (``lax.conv_general_dilated`` with ``OIW``), linear layers ``(out, in)``.

* :func:`speech_encoder` -- ``modules.SpeechEncoder``: Conv1d k1 (replicate "same" padding) -> ELU ->
  Conv1d k31 -> ELU -> Linear -> ELU (dropout off at inference).
* :func:`style_encoder` -- ``modules.StyleEncoder`` (``type="attn"``, VAE): ConvNorm1D k3 -> ReLU ->
  LayerNorm -> ConvNorm1D k3 -> ReLU -> LayerNorm, + sinusoidal positions (sin on even, cos on odd
  channels), one FFT block (4-head self-attention + residual + LayerNorm, two Conv1d k3 + residual +
  LayerNorm), mean over frames -> ``(mu, logvar)``. One clip at a time (no padding, as theirs).
* :func:`decoder` -- ``modules.Decoder``: the cell-state encoder (3 linear layers, ELU) from the initial
  pose and style, then per frame the recurrent decoder (``"normal"``: Linear + ELU, a multi-layer GRU over
  ``[hidden, pose, speech, style]``, Linear; ``"film"``: the FiLM-conditioned variant) and the character
  update of ``devectorize_output`` (root position from the previous root rotation, then the rotation).
  One ``lax.scan`` over frames; no teacher forcing.

LayerNorm uses PyTorch's eps (1e-5). References: Ghorbani et al. 2023, §3.1-3.3, §4.2; the authors'
``ZEGGS/modules.py``; Cho et al. 2014 (GRU, PyTorch gate layout r, z, n); Perez et al. 2018 (FiLM).
"""

from __future__ import annotations

import math
from typing import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.zeggs.official import quat

Params = Mapping[str, jax.Array]
LN_EPS = 1e-5


def _row(v, x):
    """``v (C,)`` shaped to broadcast against ``x (..., C)`` (explicit ranks: strict rank promotion)."""
    return jnp.reshape(v, (1,) * (x.ndim - 1) + (-1,))


def _linear(p: Params, name: str, x):
    """``x W^T + b`` with PyTorch's ``(out, in)`` weight; in :func:`decoder` the weights arrive transposed
    once (``(in, out)``, :func:`_transposed`), so the scan body multiplies without a per-frame transpose."""
    w = p[f"{name}.weight"]
    y = x @ (w if p.get("__transposed__") is not None else w.T)
    return y + _row(p[f"{name}.bias"], y)


def _transposed(p: Params) -> dict:
    """The 2-D weights as ``(in, out)`` (flagged), for the per-frame loop: measured, XLA:CPU did not hoist the
    transpose of the GRU weights out of the scan (a 3x slower rollout at batch 1)."""
    out = {k: (v.T if v.ndim == 2 and (k.endswith("weight") or "weight_" in k) else v) for k, v in p.items()}
    out["__transposed__"] = jnp.zeros(())
    return out


def _conv(x, w, b, pad_left: int, pad_right: int, mode: str = "zeros"):
    """``(B, T, C_in)`` -> ``(B, T', C_out)`` with a PyTorch ``(out, in, k)`` kernel."""
    if mode == "replicate":
        x = jnp.pad(x, ((0, 0), (pad_left, pad_right), (0, 0)), mode="edge")
        pad_left = pad_right = 0
    y = jax.lax.conv_general_dilated(x, w, (1,), [(pad_left, pad_right)], dimension_numbers=("NWC", "OIW", "NWC"),
                                     precision=jax.lax.Precision.HIGHEST)
    return y + _row(b, y)


def _layer_norm(p: Params, name: str, x):
    mean = jnp.mean(x, axis=-1, keepdims=True)
    var = jnp.mean(jnp.square(x - mean), axis=-1, keepdims=True)
    y = (x - mean) / jnp.sqrt(var + LN_EPS)
    return y * _row(p[f"{name}.weight"], y) + _row(p[f"{name}.bias"], y)


def dropout(x, rate: float, key):
    """Inverted dropout (PyTorch's ``nn.Dropout`` in training); identity when ``key`` is None (inference)."""
    if key is None or rate == 0.0:
        return x
    keep = jax.random.bernoulli(key, 1.0 - rate, x.shape)
    return jnp.where(keep, x / (1.0 - rate), jnp.zeros_like(x))


def _keys(key, n: int):
    return [None] * n if key is None else list(jax.random.split(key, n))


def speech_encoder(p: Params, x, key=None):
    """Normalised speech features ``(B, T, 81)`` -> speech encoding ``(B, T, 64)`` (``modules.SpeechEncoder``);
    ``key``: training (dropout 0.2 after each convolution), None: inference."""
    keys = _keys(key, 2)
    for i, name in enumerate(("layer0", "layer1")):
        k = p[f"{name}.weight"].shape[-1]
        left = (k - 1) // 2
        x = jax.nn.elu(_conv(x, p[f"{name}.weight"], p[f"{name}.bias"], left, k - 1 - left, "replicate"))
        x = dropout(x, 0.2, keys[i])
    return jax.nn.elu(_linear(p, "layer2", x))


def positions(frames: int, dim: int) -> np.ndarray:
    """Their ``PositionalEncoding`` table ``(frames, dim)``: ``sin`` on even, ``cos`` on odd channels."""
    pos = np.arange(frames, dtype=np.float32)[:, None]
    div = np.exp(np.arange(0, dim, 2, dtype=np.float32) * np.float32(-math.log(10000.0) / dim))
    pe = np.zeros((frames, dim), np.float32)
    pe[:, 0::2] = np.sin(pos * div)
    pe[:, 1::2] = np.cos(pos * div)
    return pe


def _attention(p: Params, name: str, x, heads: int, key=None, mask=None):
    """``nn.MultiheadAttention`` self-attention of ``(B, T, E)`` (no mask; dropout 0.1 on the attention
    weights in training)."""
    B, T, E = x.shape
    qkv = x @ p[f"{name}.in_proj_weight"].T
    qkv = qkv + _row(p[f"{name}.in_proj_bias"], qkv)
    q, k, v = jnp.split(qkv, 3, axis=-1)
    d = E // heads
    q, k, v = (a.reshape(B, T, heads, d) for a in (q, k, v))
    logits = jnp.einsum("bqhd,bkhd->bhqk", q / math.sqrt(d), k, precision=jax.lax.Precision.HIGHEST)
    if mask is not None:  # padded frames are no keys (their key_padding_mask)
        logits = jnp.where(mask[:, None, None, :], logits, jnp.asarray(-1e30, logits.dtype))
    weights = dropout(jax.nn.softmax(logits, axis=-1), 0.1, key)
    out = jnp.einsum("bhqk,bkhd->bqhd", weights, v, precision=jax.lax.Precision.HIGHEST)
    return _linear(p, f"{name}.out_proj", out.reshape(B, T, E))


def style_encoder(p: Params, x, *, heads: int = 4, key=None, mask=None):
    """Normalised example features ``(B, T, 9 + 15 J)`` -> ``(mu, logvar)``, each ``(B, D_e)``; ``key``:
    training (dropout 0.2 after each convolution block, 0.1 in the FFT block), None: inference.

    ``mask (B, T)`` (True = a real frame, real frames first): examples of several lengths padded to one (a
    single compilation). Padded frames are zeroed before every convolution -- exactly the zero padding the
    clip has alone -- are no attention keys and are left out of the mean, so each clip gets the values it
    gets alone (as their ``masked_fill`` / ``key_padding_mask``)."""
    e = "encoder"
    keys = _keys(key, 5)
    m = jnp.ones(x.shape[:2], x.dtype) if mask is None else mask.astype(x.dtype)
    m3 = m[..., None]
    h = x * m3
    for i, (conv, norm) in enumerate((("convs.0", "convs.2"), ("convs.4", "convs.6"))):
        h = jax.nn.relu(_conv(h, p[f"{e}.{conv}.conv.weight"], p[f"{e}.{conv}.conv.bias"], 1, 1))
        h = dropout(_layer_norm(p, f"{e}.{norm}", h), 0.2, keys[i]) * m3
    h = (h + positions(h.shape[1], h.shape[2])[None]) * m3
    blk = f"{e}.blocks.0"
    a = _attention(p, f"{blk}.attention.multi_head_attention", h, heads, keys[2], None if mask is None else mask)
    a = dropout(a, 0.1, keys[3])
    h = _layer_norm(p, f"{blk}.attention.layer_norm", a + h) * m3
    f = jax.nn.relu(_conv(h, p[f"{blk}.feed_forward.convs.0.conv.weight"], p[f"{blk}.feed_forward.convs.0.conv.bias"],
                          1, 1)) * m3
    f = _conv(f, p[f"{blk}.feed_forward.convs.2.conv.weight"], p[f"{blk}.feed_forward.convs.2.conv.bias"], 1, 1)
    f = dropout(f, 0.1, keys[4])
    h = _layer_norm(p, f"{blk}.feed_forward.layer_norm", f + h) * m3
    pooled = jnp.sum(h, axis=1) / jnp.maximum(jnp.sum(m3, axis=1), 1.0)
    half = pooled.shape[-1] // 2
    return pooled[:, :half], pooled[:, half:]


def _gru_layers(p: Params, prefix: str) -> int:
    n = 0
    while f"{prefix}.weight_ih_l{n}" in p:
        n += 1
    return n


def _gru(p: Params, prefix: str, x, hidden):
    """One step of a multi-layer ``nn.GRU``: ``x (B, I)``, hidden ``(L, B, H)`` -> output, new hidden."""
    new = []
    for layer in range(hidden.shape[0]):
        h = hidden[layer]
        t = p.get("__transposed__") is not None
        w_ih, w_hh = p[f"{prefix}.weight_ih_l{layer}"], p[f"{prefix}.weight_hh_l{layer}"]
        gi = x @ (w_ih if t else w_ih.T)
        gi = gi + _row(p[f"{prefix}.bias_ih_l{layer}"], gi)
        gh = h @ (w_hh if t else w_hh.T)
        gh = gh + _row(p[f"{prefix}.bias_hh_l{layer}"], gh)
        H = h.shape[-1]
        r = jax.nn.sigmoid(gi[:, :H] + gh[:, :H])
        z = jax.nn.sigmoid(gi[:, H:2 * H] + gh[:, H:2 * H])
        n = jnp.tanh(gi[:, 2 * H:] + r * gh[:, 2 * H:])
        x = (1.0 - z) * n + z * h
        new.append(x)
    return x, jnp.stack(new)


def _recurrent_step(p: Params, cond: str, pose, speech, style, hidden):
    r = "recurrent_decoder"
    if cond == "normal":
        inp = jnp.concatenate([pose, speech, style], axis=-1)
        h = jax.nn.elu(_linear(p, f"{r}.layer0", inp))
        out, hidden = _gru(p, f"{r}.layer1", jnp.concatenate([h, inp], axis=-1), hidden)
        return _linear(p, f"{r}.layer2", out), hidden
    # "film": FiLM of the hidden layers by the style (gammas + 1, betas), as modules.RecurrentDecoderFiLM
    gammas = _linear(p, f"{r}.gammas_predictor.linear_layer", style) + 1.0
    betas = _linear(p, f"{r}.betas_predictor.linear_layer", style)
    H = gammas.shape[-1] // 2
    inp = jnp.concatenate([pose, speech], axis=-1)
    h = jax.nn.elu(_linear(p, f"{r}.layer0", inp)) * gammas[:, :H] + betas[:, :H]
    out, hidden = _gru(p, f"{r}.layer1", jnp.concatenate([h, inp], axis=-1), hidden)
    h = jax.nn.elu(_linear(p, f"{r}.layer2", out)) * gammas[:, H:] + betas[:, H:]
    return _linear(p, f"{r}.layer3", h), hidden


def vectorize(state: dict, gaze_pos, in_mean, in_std):
    """``modules.vectorize_input``: the normalised decoder input ``(B, 9 + 15 J)`` of a pose state."""
    B = state["lpos"].shape[0]
    gaze_dir = quat.mul_vec(quat.inv(state["root_rot"], jnp), gaze_pos - state["root_pos"], jnp)
    parts = [state[k].reshape(B, -1) for k in ("root_vel", "root_vrt", "lpos", "ltxy", "lvel", "lvrt")]
    x = jnp.concatenate(parts + [gaze_dir], axis=-1)
    return (x - _row(in_mean, x)) / _row(in_std, x)


def devectorize(pred, root_pos, root_rot, joints: int, dt: float, out_mean, out_std) -> dict:
    """``modules.devectorize_output``: denormalise a prediction and integrate the root (previous rotation)."""
    B = pred.shape[0]
    y = pred * _row(out_std, pred) + _row(out_mean, pred)
    J = joints
    state = dict(root_vel=y[:, 0:3], root_vrt=y[:, 3:6], lpos=y[:, 6:6 + 3 * J].reshape(B, J, 3),
                 ltxy=y[:, 6 + 3 * J:6 + 9 * J].reshape(B, J, 2, 3),
                 lvel=y[:, 6 + 9 * J:6 + 12 * J].reshape(B, J, 3),
                 lvrt=y[:, 6 + 12 * J:6 + 15 * J].reshape(B, J, 3))
    state["root_pos"] = quat.mul_vec(root_rot, state["root_vel"] * dt, jnp) + root_pos
    turn = quat.from_helical(quat.mul_vec(root_rot, state["root_vrt"] * dt, jnp), xp=jnp)
    state["root_rot"] = quat.mul(turn, root_rot, jnp)
    return state


STATE_KEYS = ("root_pos", "root_rot", "root_vel", "root_vrt", "lpos", "ltxy", "lvel", "lvrt")


def decoder(p: Params, state0: dict, gaze_pos, speech, style, stats: Mapping[str, jax.Array], *, dt: float,
            cond: str = "normal") -> dict:
    """Roll the decoder out over ``speech (B, T, D_S)`` from the pose state ``state0`` (each ``(B, ...)``).

    ``gaze_pos (B, T, 3)`` (the authors repeat the first frame's), ``style (B, T, D_e)`` (per frame: blends
    and stitches) and ``stats`` (``anim_input_mean/std``, ``anim_output_mean/std``). Returns the state keys
    of :data:`STATE_KEYS`, each ``(B, T, ...)``; frame 0 is ``state0`` (their ``Decoder.forward``).
    References: the authors' ``modules.Decoder``; Ghorbani et al. 2023, §3.3 (Fig. 4).
    """
    in_mean, in_std = stats["anim_input_mean"], stats["anim_input_std"]
    out_mean, out_std = stats["anim_output_mean"], stats["anim_output_std"]
    J = state0["lpos"].shape[1]
    p = _transposed(p)
    c = "cell_state_encoder"
    h = jax.nn.elu(_linear(p, f"{c}.layer0", jnp.concatenate(
        [vectorize(state0, gaze_pos[:, 0], in_mean, in_std), style[:, 0]], axis=-1)))
    h = jax.nn.elu(_linear(p, f"{c}.layer1", h))
    h = _linear(p, f"{c}.layer2", h)
    layers = _gru_layers(p, "recurrent_decoder.layer1")
    hidden = jnp.swapaxes(h.reshape(h.shape[0], layers, -1), 0, 1)

    def step(carry, xs):
        st, hid = carry
        gaze_t, speech_t, style_t = xs
        pred, hid = _recurrent_step(p, cond, vectorize(st, gaze_t, in_mean, in_std), speech_t, style_t, hid)
        new = devectorize(pred, st["root_pos"], st["root_rot"], J, dt, out_mean, out_std)
        return (new, hid), new

    init = {k: state0[k] for k in STATE_KEYS}
    xs = tuple(jnp.swapaxes(a[:, 1:], 0, 1) for a in (gaze_pos, speech, style))
    _, seq = jax.lax.scan(step, (init, hidden), xs)
    return {k: jnp.concatenate([init[k][:, None], jnp.swapaxes(seq[k], 0, 1)], axis=1) for k in STATE_KEYS}

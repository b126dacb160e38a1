"""NumPy reference of the TGST transfer forward pass (paper variant), on the same Flax parameter tree.

Written from the paper and docs/design.md §3, independently of the Flax modules' code paths: plain im2col
convolutions, a dense band-masked attention, explicit LayerNorm and exact (erf) GELU. It is the third
implementation of the benchmark's transfer case and a test oracle (``tests/integration/test_bench_harness.py`` checks
it against ``jaxgest.tgst.model.transfer_arrays``).

References: Kuriyama et al. 2022, App. A (autoencoder), eq. 1 (tokens), eqs. 2-4 (transformer, swap),
§3.3 (cross-fade), eq. 19 (hard swap).
"""

from __future__ import annotations

import math

import numpy as np

def gelu(x: np.ndarray) -> np.ndarray:
    """Exact GELU, x * Phi(x); erf through a float64 rational approximation (|err| < 1.2e-7)."""
    # Abramowitz-Stegun 7.1.26 is too coarse; use the complementary-error-function series of Numerical
    # Recipes (erfcc, fractional error < 1.2e-7 everywhere), fully vectorised.
    z = np.abs(x) / math.sqrt(2.0)
    t = 1.0 / (1.0 + 0.5 * z)
    poly = -z * z - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (-0.18628806 + t * (
        0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))))
    erfc = t * np.exp(poly)
    erf = np.where(x >= 0, 1.0 - erfc, erfc - 1.0)
    return 0.5 * x * (1.0 + erf)


def conv1d(x: np.ndarray, kernel: np.ndarray, bias: np.ndarray, stride: int = 1) -> np.ndarray:
    """``(B, F, Cin)`` * ``(k, Cin, Cout)``, padding k//2 both sides (PyTorch), stride -> ``(B, F', Cout)``."""
    k = kernel.shape[0]
    p = k // 2
    xp = np.pad(x, ((0, 0), (p, p), (0, 0)))
    f_out = (x.shape[1] + 2 * p - k) // stride + 1
    cols = np.stack([xp[:, i : i + stride * (f_out - 1) + 1 : stride] for i in range(k)], axis=2)  # (B,F',k,C)
    return np.einsum("bfkc,kco->bfo", cols, kernel) + bias


def upsample2(x: np.ndarray) -> np.ndarray:
    """x2 linear upsampling, half-pixel centres, edges clamped (torch align_corners=False)."""
    prev = np.concatenate([x[:, :1], x[:, :-1]], axis=1)
    nxt = np.concatenate([x[:, 1:], x[:, -1:]], axis=1)
    out = np.empty((x.shape[0], 2 * x.shape[1], x.shape[2]), x.dtype)
    out[:, 0::2] = 0.75 * x + 0.25 * prev
    out[:, 1::2] = 0.75 * x + 0.25 * nxt
    return out


def encode(ae: dict, x: np.ndarray) -> np.ndarray:
    e = ae["encoder"]
    x = gelu(conv1d(x, e["conv_0"]["kernel"], e["conv_0"]["bias"], 1))
    x = gelu(conv1d(x, e["conv_1"]["kernel"], e["conv_1"]["bias"], 2))
    return gelu(conv1d(x, e["conv_2"]["kernel"], e["conv_2"]["bias"], 2))


def decode(dec: dict, z: np.ndarray) -> np.ndarray:
    x = gelu(conv1d(upsample2(z), dec["conv_0"]["kernel"], dec["conv_0"]["bias"]))
    x = gelu(conv1d(upsample2(x), dec["conv_1"]["kernel"], dec["conv_1"]["bias"]))
    return conv1d(x, dec["conv_2"]["kernel"], dec["conv_2"]["bias"])


def tokenize(z: np.ndarray, h: int = 2) -> np.ndarray:
    b, t, d = z.shape
    tp = -(-t // h) * h
    z = np.pad(z, ((0, 0), (0, tp - t), (0, 0)), mode="edge")
    chunks = z.reshape(b, tp // h, h * d)
    return np.concatenate([chunks[:, :-1], chunks[:, 1:]], axis=2)


def detokenize(tokens: np.ndarray, length: int, h: int = 2) -> np.ndarray:
    b, n, dg = tokens.shape
    d = dg // (2 * h)
    halves = tokens.reshape(b, n, 2, h, d)
    first, second = halves[:, :, 0], halves[:, :, 1]
    a = (np.arange(1, h + 1) / (h + 1))[None, None, :, None]
    middle = (1 - a) * second[:, :-1] + a * first[:, 1:]
    chunks = np.concatenate([first[:, :1], middle, second[:, -1:]], axis=1)
    return chunks.reshape(b, (n + 1) * h, d)[:, :length]


def layer_norm(x, p, eps=1e-5):
    mu = x.mean(-1, keepdims=True)
    var = ((x - mu) ** 2).mean(-1, keepdims=True)
    return (x - mu) / np.sqrt(var + eps) * p["scale"] + p["bias"]


def dense(x, p):
    return x @ p["kernel"] + p["bias"]


def softmax(s, axis=-1):
    s = s - s.max(axis=axis, keepdims=True)
    e = np.exp(s)
    return e / e.sum(axis=axis, keepdims=True)


def positions(num, dim):
    pos = np.arange(num)[:, None]
    freq = np.exp(np.arange(0, dim, 2) * (-math.log(10000.0) / dim))
    pe = np.zeros((num, dim))
    pe[:, 0::2] = np.sin(pos * freq)
    pe[:, 1::2] = np.cos(pos * freq)
    return pe


def encoder(p: dict, tokens: np.ndarray, omega: int) -> np.ndarray:
    """T_E (paper variant, one shared pre-LN): dense band mask, CLS first."""
    b, n, d = tokens.shape
    x = np.concatenate([np.broadcast_to(p["cls"], (b, 1, d)), tokens], axis=1) + positions(n + 1, d)[None]
    z = layer_norm(x, p["ln"])
    q, k, v = dense(z, p["query"]), dense(z, p["key"]), dense(z, p["value"])
    idx = np.arange(n + 1)
    mask = (idx[:, None] == 0) | (idx[None, :] == 0) | (np.abs(idx[:, None] - idx[None, :]) <= omega)
    s = np.where(mask[None], q @ k.transpose(0, 2, 1) / math.sqrt(d), -1e9)
    x = x + dense(softmax(s) @ v, p["out"])
    return x + mlp(p["mlp"], layer_norm(x, p["ln"]))


def mlp(p, x):
    return dense(gelu(dense(x, p["fc_0"])), p["fc_1"])


def decoder(p: dict, enc_c: np.ndarray, enc_s: np.ndarray) -> np.ndarray:
    c, s = enc_c[:, 1:], enc_s[:, 1:]
    zc, zs = layer_norm(c, p["ln"]), layer_norm(s, p["ln"])
    d = c.shape[-1]
    w = softmax(dense(zc, p["query"]) @ dense(zs, p["key"]).transpose(0, 2, 1) / math.sqrt(d))
    x = c + dense(w @ dense(zs, p["value"]), p["out"])
    return x + mlp(p["mlp"], layer_norm(x, p["ln"]))


def pad_clip(x: np.ndarray, edge: int) -> np.ndarray:
    """Clip ends (docs/design.md §3): ``edge`` copies of the first frame before the clip, copies of the last frame after
    it (at least ``edge``) up to a multiple of 16 frames in total."""
    f = x.shape[1]
    total = -(-(f + 2 * edge) // 16) * 16
    return np.pad(x, ((0, 0), (edge, total - f - edge), (0, 0)), mode="edge")


def transfer(params: dict, content: np.ndarray, style: np.ndarray, *, omega: int = 20, hard: bool = False,
             edge: int = 16):
    """Content ``(B, Fc, 39)`` in the style of ``(B, Fs, 39)`` -> (upper ``(B, Fc, 39)``, lower ``(B, Fc, 24)``).

    Both clips are edge-padded at both ends by ``edge`` frames (the presets' ``edge_frames``); the content
    keeps its padded latents and the output is trimmed, the style is cut to its real latent frames (4x time
    reduction) before tokenizing."""
    params = _np_tree(params)
    ae, tr = params["autoencoder"], params["transformer"]
    b, fc, _ = content.shape
    fs = style.shape[1]
    zc = encode(ae, pad_clip(np.asarray(content, np.float64), edge))
    zs = encode(ae, pad_clip(np.asarray(style, np.float64), edge))
    if edge:
        zs = zs[:, edge // 4:edge // 4 + -(-fs // 4)]
    gc, gs = tokenize(zc), tokenize(zs)
    enc_c, enc_s = encoder(tr["encoder"], gc, omega), encoder(tr["encoder"], gs, omega)
    dec = decoder(tr["decoder"], enc_c, enc_s)
    logits = dec @ enc_s[:, 1:].transpose(0, 2, 1)
    if hard:
        w = np.eye(logits.shape[-1])[np.argmax(logits, axis=-1)]
    else:
        w = softmax(logits)
    zx = detokenize(w @ gs, zc.shape[1])
    return (decode(ae["upper_decoder"], zx)[:, edge:edge + fc], decode(ae["lower_decoder"], zx)[:, edge:edge + fc])


def _np_tree(tree):
    if isinstance(tree, dict):
        return {k: _np_tree(v) for k, v in tree.items()}
    return np.asarray(tree, np.float64)

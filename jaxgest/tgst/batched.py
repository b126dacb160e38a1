"""Batched, length-bucketed TGST transfers of many content/style pairs, and soft-swap diagnostics.

:class:`BatchedTransfer` runs every method of one pair in one jitted call, with content and style padded to
:func:`bucket_length`, so a whole dataset costs a few compilations (used by :func:`jaxgest.tgst.evaluate.
evaluate`). :func:`swap_diagnostics` summarises how the soft swap blends style tokens.
References: Kuriyama et al. 2022, eq. 4 (swap weights), §4.3.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax
import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.tgst import model as tgst_model
from jaxgest.tgst.config import InferenceConfig

DEFAULT_BUCKET = InferenceConfig.bucket  # length-bucket ratio of batched transfers


def bucket_length(frames: int, ratio: float = DEFAULT_BUCKET, *, multiple: int = 16, base: int = 64) -> int:
    """Padded length of a ``frames``-frame clip: the smallest of base, base * ratio, base * ratio^2, ...
    (each rounded up to a multiple of ``multiple``) that holds it. ``ratio <= 1``: no bucketing (the
    clip's own length). Few distinct lengths -> few compilations; at most ``ratio``x the frames.
    """
    if ratio <= 1.0:
        return int(frames)
    k = base
    while k < frames:
        k = max(k + multiple, int(math.ceil(k * ratio / multiple)) * multiple)
    return k


def _num_tokens(frames: int, cfg) -> int:
    """Tokens whose frames all lie in the first ``frames`` frames (token m covers latent frames
    m*h .. m*h + w - 1)."""
    red, w, h = cfg.autoencoder.time_reduction, cfg.token_width, cfg.token_stride
    latent = frames // red
    return 0 if latent < w else (latent - w) // h + 1


def _pair_outputs(params, content_upper, style_upper, content_frames, style_frames, *, cfg, methods: tuple,
                  weights: bool):
    """Every method's transfer of one pair padded to its buckets (``*_frames``: the real frames, traced, so
    one compilation serves a bucket), plus the soft-swap weights (None without ``weights``)."""
    frames = dict(content_frames=content_frames, style_frames=style_frames)
    outs = {}
    for m in methods:
        up, lo, _ = tgst_model.transfer_arrays(params, content_upper, style_upper, cfg=cfg, method=m, **frames)
        outs[m] = (up, lo)
    w = tgst_model.swap_weights(params, content_upper, style_upper, cfg=cfg, **frames) if weights else None
    return outs, w


#: one jitted call per pair; jit's own cache compiles once per (config, methods, bucket shapes)
_pair_jit = jax.jit(_pair_outputs, static_argnames=("cfg", "methods", "weights"))


class BatchedTransfer:
    """Transfers of many pairs with a trained :class:`jaxgest.tgst.api.TGSTModel` and few compilations.

    Each clip is converted to body exp-maps at the model rate once; content and style are padded at the end
    to :func:`bucket_length` (``ratio``; <= 1 = exact, no padding), every method runs in one jitted call per
    pair, and the outputs are cut back to the content's frames and written on its skeleton
    (:meth:`TGSTModel.to_motion`). Pairs that share a bucket shape share one compilation.

    Padding: the clips are padded at the end (``pad_mode``, any ``numpy.pad`` mode; default "edge", the
    last frame held, as the exact-length transfer pads them) and the padding is masked
    (:func:`jaxgest.tgst.model.mask_padding`): the swap pool holds exactly the exact-length style tokens
    (padded tokens get weight 0 and are never attended to), the baselines' statistics use the real latent
    frames, and the padded output frames are cut off. The padding reaches the real frames only through the
    autoencoder's convolutions at the clip's end, where "edge" gives the frames the exact-length transfer
    sees, so the result equals the exact-length one to float error (tests/unit/test_tgst_padding_mask.py).
    (Before issue 58 the padding was "wrap" and unmasked: 4-13 % of the soft swap's weight landed on the
    wrapped copies and the seam token of a mirrored style input.)
    """

    def __init__(self, model, methods: Sequence[str], *, ratio: float = DEFAULT_BUCKET, diagnostics: bool = True,
                 pad_mode: str = "edge"):
        self.model, self.methods, self.ratio, self.pad_mode = model, tuple(methods), float(ratio), pad_mode
        self.diagnostics = diagnostics and any(m in ("soft", "hard") for m in self.methods)
        self._arrays: dict = {}
        self.shapes: set = set()

    def body(self, clip, role: str) -> np.ndarray:
        key = id(clip)
        if key not in self._arrays:
            self._arrays[key] = (clip, self.model.body_arrays(clip.motion, role))
        return self._arrays[key][1]

    def run(self, pair) -> tuple[dict, dict | None]:
        """``({method: Motion}, swap diagnostics or None)`` of one pair (``pair.content`` / ``pair.style``:
        dataset clips, as in :class:`jaxgest.tgst.evaluate.Pair`); DataError for unusable clips."""
        cu, su = self.body(pair.content, "content"), self.body(pair.style, "style")
        fc, fs = len(cu), len(su)
        bc, bs = bucket_length(fc, self.ratio), bucket_length(fs, self.ratio)
        self.shapes.add((bc, bs))
        c = np.pad(cu, ((0, bc - fc), (0, 0)), mode=self.pad_mode)[None]
        s = np.pad(su, ((0, bs - fs), (0, 0)), mode=self.pad_mode)[None]
        outs, w = _pair_jit(self.model.params, c, s, np.int32(fc), np.int32(fs), cfg=self.model.cfg,
                            methods=self.methods, weights=self.diagnostics)
        results = {}
        for m, (up, lo) in outs.items():
            results[m] = self.model.to_motion(np.asarray(up[0, :fc]), np.asarray(lo[0, :fc]),
                                              pair.content.motion)
        diag = None
        if w is not None:
            cfg = self.model.cfg
            nc, ns = _num_tokens(fc, cfg), int(tgst_model.exact_token_count(fs, cfg=cfg, role="style"))
            diag = swap_diagnostics(np.asarray(w[0]), nc, ns) if nc and ns else None
        return results, diag


def argmax_steps(argmax) -> dict:
    """How the chosen style tokens ``(Nc,)`` move from one content token to the next: the fractions of
    steps of exactly +1 (``"one"``), 0 (``"zero"``), < 0 (``"back"``) and > 2 (``"far"``); NaN for fewer
    than two tokens. Half-overlapping tokens (eq. 1) are cross-faded, so only a +1 step blends frames that
    followed each other in the style clip."""
    a = np.asarray(argmax)
    if a.ndim != 1:
        raise DataError(f"argmax_steps: expected token indices (Nc,), got shape {a.shape}")
    if len(a) < 2:
        return {k: float("nan") for k in ("one", "zero", "back", "far")}
    d = np.diff(a)
    return {"one": float(np.mean(d == 1)), "zero": float(np.mean(d == 0)), "back": float(np.mean(d < 0)),
            "far": float(np.mean(d > 2))}


def swap_diagnostics(weights: np.ndarray, num_queries: int | None = None, num_style: int | None = None) -> dict:
    """How a soft swap blends: statistics of swap weights ``(Nc, Ns)`` (rows on the simplex).

    Rows are content tokens from the content's first frame, columns style tokens from the style's first
    frame (same model rate, so equal indices are equal times). Only the first ``num_queries`` rows (tokens of
    the real content) are used; columns past ``num_style`` (the swap pool's size) are padding, whose total
    weight is reported as ``padding_mass`` (0 for :class:`BatchedTransfer`, which masks it). Returns::

        {"max_weight": mean over rows of max_m w_nm,
         "effective_tokens": mean over rows of 1 / sum_m w_nm^2 (1 = one token, Ns = uniform),
         "argmax_within_1": fraction of rows whose argmax m has |m - n| <= 1,
         "chance_within_1": that fraction for an argmax uniform over the Ns real style tokens,
         "step_one", "step_zero", "step_back", "step_far": of consecutive rows, the fractions whose argmax
             advances by exactly one style token (the style's own timing), stays, goes back, or jumps
             ahead by more than two (:func:`argmax_steps`; NaN with one row),
         "padding_mass", "num_queries", "num_style"}

    References: Kuriyama et al. 2022, eq. 4 (the soft swap weights W).
    """
    w = np.asarray(weights, np.float64)
    if w.ndim != 2 or w.size == 0:
        raise DataError(f"swap_diagnostics: expected weights (Nc, Ns), got shape {w.shape}")
    nq = w.shape[0] if num_queries is None else min(int(num_queries), w.shape[0])
    ns = w.shape[1] if num_style is None else min(int(num_style), w.shape[1])
    w = w[:nq]
    n = np.arange(nq)
    am = w.argmax(axis=1)
    lo, hi = np.maximum(n - 1, 0), np.minimum(n + 1, ns - 1)
    chance = np.maximum(hi - lo + 1, 0) / ns
    return {
        "max_weight": float(w.max(axis=1).mean()),
        "effective_tokens": float((1.0 / np.sum(w**2, axis=1)).mean()),
        "argmax_within_1": float(np.mean(np.abs(am - n) <= 1)),
        "chance_within_1": float(chance.mean()),
        "padding_mass": float(w[:, ns:].sum(axis=1).mean()),
        **{f"step_{k}": v for k, v in argmax_steps(am).items()},
        "num_queries": int(nq),
        "num_style": int(ns),
    }

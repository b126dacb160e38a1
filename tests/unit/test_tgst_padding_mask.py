"""Padded style tokens are out of the swap pool (issue 58, item 1): masked padding gets weight exactly 0, and a
transfer of clips padded to a length bucket equals the exact-length transfer (jaxgest.tgst.batched)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgest.tgst import batched as B
from jaxgest.tgst import model as M
from jaxgest.tgst import swap
from jaxgest.tgst.config import preset

METHODS = ("soft", "hard", "adain", "avatarnet", "coherent")


def _pools(seed=0, nc=9, ns=7, pad=5, d=8):
    """Decoded content, encoded style with CLS, and the same style with ``pad`` tokens appended that are more
    similar to every content token than any real one (so an unmasked swap would favour them)."""
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(2, nc, d)).astype(np.float32)
    s = rng.normal(size=(2, 1 + ns, d)).astype(np.float32)
    extra = 3.0 * np.repeat(c.mean(axis=1, keepdims=True), pad, axis=1)
    padded = np.concatenate([s, extra], axis=1)
    valid = np.broadcast_to(np.arange(ns + pad)[None] < ns, (2, ns + pad))
    return jnp.asarray(c), jnp.asarray(s), jnp.asarray(padded), jnp.asarray(valid), ns


@pytest.mark.parametrize("similarity", ["dot", "scaled"])
def test_padded_style_tokens_get_exactly_zero_weight(similarity):
    c, s, padded, valid, ns = _pools()
    for temperature in (1.0, 0.05):
        unmasked = swap.soft_swap_weights(c, padded, temperature, similarity=similarity)
        assert float(jnp.mean(jnp.sum(unmasked[..., ns:], -1))) > 0.1  # control: the padding would take weight
        w = swap.soft_swap_weights(c, padded, temperature, similarity=similarity, style_valid=valid)
        assert np.all(np.asarray(w[..., ns:]) == 0.0)
        np.testing.assert_allclose(w[..., :ns], swap.soft_swap_weights(c, s, temperature, similarity=similarity),
                                   atol=1e-6)
    hard = swap.hard_swap_weights(c, padded, similarity=similarity, style_valid=valid)
    assert np.all(np.asarray(hard[..., ns:]) == 0.0)
    np.testing.assert_array_equal(hard[..., :ns], swap.hard_swap_weights(c, s, similarity=similarity))
    assert np.any(np.asarray(swap.hard_swap_weights(c, padded, similarity=similarity)[..., ns:]) == 1.0)
    coh = swap.coherent_swap_weights(c, padded, similarity=similarity, style_valid=valid)
    assert np.all(np.asarray(coh[..., ns:]) == 0.0)
    np.testing.assert_array_equal(coh[..., :ns], swap.coherent_swap_weights(c, s, similarity=similarity))


def test_constant_rate_path_with_padding_is_the_path_of_the_real_tokens():
    """Random scores with padded style and content tokens that score higher than any real one: the masked
    path is the unpadded set's path on the real content tokens (ends, ties and overruns included)."""
    rng = np.random.default_rng(1)
    path = jax.jit(swap.constant_rate_path)  # one compilation per shape: few shapes, many draws
    for nc, ns in ((1, 1), (5, 4), (13, 4), (5, 11), (13, 11)):
        for _ in range(8):
            scores = rng.normal(size=(1, nc, ns)).astype(np.float32)
            full = np.pad(scores, ((0, 0), (0, 16 - nc), (0, 14 - ns)), constant_values=5.0)
            valid = np.arange(14)[None] < ns
            rows = np.arange(16)[None] < nc
            exact = np.asarray(path(jnp.asarray(scores)))
            masked = np.asarray(path(jnp.asarray(full), valid=jnp.asarray(valid), query_valid=jnp.asarray(rows)))
            np.testing.assert_array_equal(masked[:, :nc], exact)
            assert masked.max() < ns
    unmasked = np.asarray(path(jnp.asarray(full)))  # control: without the masks the path runs into the padding
    assert unmasked.max() >= ns


@pytest.fixture(scope="module")
def tiny():
    cfg = preset("tiny").model
    return cfg, M.init_params(cfg, jax.random.key(0))


def _clip(frames, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[:, None] / 60.0
    return (0.3 * np.sin(2 * np.pi * (0.5 + rng.random(39)) * t + 6 * rng.random(39))).astype(np.float32)


def test_bucketed_transfer_equals_exact_length_transfer(tiny):
    """Content and style padded at the end to their length buckets (held last frame) with the real frame counts
    given: every method's result on the real frames equals the exact-length transfer, and the soft swap's
    weight on the padded style tokens is exactly 0. Control: the same padding unmasked changes the result."""
    cfg, params = tiny
    fc, fs = 203, 157
    cu, su = _clip(fc, 0), _clip(fs, 1)
    bc, bs = B.bucket_length(fc), B.bucket_length(fs)
    assert bc > fc and bs > fs and M.exact_token_count(bs, cfg=cfg, role="style") > \
        M.exact_token_count(fs, cfg=cfg, role="style")  # really padded, by whole tokens
    c = np.pad(cu, ((0, bc - fc), (0, 0)), mode="edge")[None]
    s = np.pad(su, ((0, bs - fs), (0, 0)), mode="edge")[None]
    outs, w = B._pair_jit(params, c, s, np.int32(fc), np.int32(fs), cfg=cfg, methods=METHODS, weights=True)
    for m in METHODS:
        up, lo, _ = M.transfer_arrays(params, cu[None], su[None], cfg=cfg, method=m)
        np.testing.assert_allclose(outs[m][0][0, :fc], up[0], atol=1e-5, err_msg=m)
        np.testing.assert_allclose(outs[m][1][0, :fc], lo[0], atol=1e-5, err_msg=m)
    ns = int(M.exact_token_count(fs, cfg=cfg, role="style"))
    exact_w = M.swap_weights(params, cu[None], su[None], cfg=cfg)
    assert exact_w.shape[2] == ns and w.shape[2] > ns
    assert np.all(np.asarray(w[0, :, ns:]) == 0.0)
    nq = B._num_tokens(fc, cfg)
    np.testing.assert_allclose(w[0, :nq, :ns], exact_w[0, :nq], atol=1e-5)
    unmasked = M.transfer_arrays(params, c, s, cfg=cfg, method="soft")[0]
    soft = M.transfer_arrays(params, cu[None], su[None], cfg=cfg, method="soft")[0]
    assert float(jnp.abs(unmasked[0, :fc] - soft[0]).max()) > 1e-3


def test_masked_frames_are_traced_not_static(tiny):
    """Two real lengths in one bucket share one compilation (the masks are data, not shapes)."""
    cfg, params = tiny
    traces = []
    fn = jax.jit(lambda p, c, s, fc, fs: (traces.append(1), M.transfer_arrays(
        p, c, s, cfg=cfg, method="soft", content_frames=fc, style_frames=fs)[0])[1])
    c, s = _clip(64, 2)[None], _clip(64, 3)[None]
    for fc, fs in ((64, 64), (50, 40)):
        assert fn(params, c, s, np.int32(fc), np.int32(fs)).shape == (1, 64, 39)
    assert len(traces) == 1

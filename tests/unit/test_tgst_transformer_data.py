"""Transformer training data like the authors' (``style_tokens="clip_and_mirror"``): the style token set is the
whole style clip followed by its mirror, padded to a length bucket with a mask; the mask keeps the padding out
of attention, the swap and the losses."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgest.tgst import data as tdata
from jaxgest.tgst import model as M
from jaxgest.tgst.config import TransformerTrainConfig
from jaxgest.tgst.losses import transformer_loss_terms
from jaxgest.tgst.steps import create_transformer_state, make_transformer_train_step
from jaxgest.tgst.tokens import tokenize
from jaxgest.tgst.transformer import StyleTransformerEncoder
from jaxgest.tgst.trainer import apply_overrides

from tgst_testing import CFG, FULL, random_params, smooth_motion

MODE = apply_overrides(FULL, {"train.transformer.style_tokens": "clip_and_mirror",
                              "train.transformer.window": 64, "train.transformer.batch_size": 3})


def _body(lengths, seed=0):
    """Synthetic BodyData: distinct smooth clips; the 'mirror' a different smooth clip of the same length."""
    up = [np.asarray(smooth_motion(seed + i, 1, n, 39)[0]) for i, n in enumerate(lengths)]
    mup = [np.asarray(smooth_motion(100 + seed + i, 1, n, 39)[0]) for i, n in enumerate(lengths)]
    lo = [np.zeros((n, 24), np.float32) for n in lengths]
    return tdata.BodyData(up, lo, mup, [x.copy() for x in lo], [f"clip{i}" for i in range(len(lengths))], 60.0,
                          [f"c{i}" for i in range(len(lengths))])


def test_style_set_is_whole_clip_and_mirror():
    data = _body([70, 96, 130, 150, 81])
    transition = 30
    for step in range(4):
        batch = tdata.transformer_batch(data, MODE, seed=1, step=step)
        c, s, v = batch["content"], batch["style"], batch["style_valid"]
        assert c.shape == (3, 64, 39) and s.shape[0] == 3 and s.shape[1] % 16 == 0
        assert v.dtype == bool and v.shape == (3, int(tdata.style_token_count(s.shape[1], MODE)))
        for i in range(3):
            ci = [k for k, u in enumerate(data.upper) if any(np.array_equal(u[a:a + 64], c[i])
                                                            for a in range(len(u) - 63))]
            assert ci, "content is not a window of a training clip"
            whole = {k: tdata.append_mirror(data.upper[k], data.mirrored_upper[k], transition)
                     for k in range(5) if k not in ci}
            match = [k for k, x in whole.items() if np.array_equal(s[i, :len(x)], x)]
            assert len(match) == 1, "style is not another clip whole followed by its mirror"
            x = whole[match[0]]
            assert len(x) == len(data.upper[match[0]]) * 2 - transition
            assert np.array_equal(s[i, len(x):], np.repeat(x[-1:], s.shape[1] - len(x), axis=0))  # edge padding
            assert v[i].sum() == tdata.style_token_count(len(x), MODE) and v[i, :v[i].sum()].all()
        # the mirror really follows: the frames after the blend are the mirror's
        k = match[0]
        n = len(data.upper[k])
        np.testing.assert_array_equal(x[n:], data.mirrored_upper[k][transition:])
        np.testing.assert_array_equal(x[:n - transition], data.upper[k][:n - transition])


def test_append_mirror_blend_is_a_slerp_path():
    a = np.zeros((40, 39), np.float32)
    b = np.tile(np.array([0.0, 0.0, 1.0] * 13, np.float32), (40, 1))  # 1 rad about z
    x = tdata.append_mirror(a, b, 10)
    assert x.shape == (70, 39)
    np.testing.assert_allclose(x[30:40, 2], np.arange(10) / 10, atol=1e-6)  # slerp of a fixed axis = lerp
    np.testing.assert_array_equal(x[40:], b[10:])


def test_long_style_clip_is_capped():
    cfg = apply_overrides(MODE, {"train.transformer.style_max_frames": 48})
    data = _body([70, 96, 400])
    for step in range(6):
        b = tdata.transformer_batch(data, cfg, seed=0, step=step)
        assert b["style_valid"].sum(1).max() <= tdata.style_token_count(2 * 48 - 30, cfg)


def test_valid_mask_matches_the_tokens_the_model_sees():
    data = _body([70, 96, 130, 150])
    batch = tdata.transformer_batch(data, MODE, seed=3, step=0)
    params = random_params(0)
    _, zs, _, _ = M.encode_pair(params["autoencoder"], jnp.asarray(batch["content"]), jnp.asarray(batch["style"]),
                                cfg=CFG)
    assert tokenize(zs, CFG.token_width, CFG.token_stride).shape[1] == batch["style_valid"].shape[1]


@pytest.mark.parametrize("impl", ["blockwise", "dense"])
def test_encoder_ignores_masked_padding(impl):
    tcfg = dataclasses.replace(CFG.transformer, attention_impl=impl)
    params = {"params": random_params(0)["transformer"]["encoder"]}
    enc = StyleTransformerEncoder(tcfg)
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.normal(size=(2, 9, 64)), jnp.float32)
    pad = jnp.concatenate([x, jnp.asarray(rng.normal(size=(2, 6, 64)) * 5, jnp.float32)], axis=1)
    valid = jnp.arange(15)[None] < 9
    valid = jnp.broadcast_to(valid, (2, 15))
    y, aux = enc.apply(params, x)
    yp, auxp = enc.apply(params, pad, valid)
    np.testing.assert_allclose(yp[:, :10], y, atol=2e-5)
    np.testing.assert_allclose(auxp["cls"], aux["cls"], atol=2e-5)
    y_nomask, _ = enc.apply(params, pad)
    assert np.abs(np.asarray(y_nomask[:, 0] - y[:, 0])).max() > 1e-3  # without the mask the padding leaks in


@jax.jit
def _terms(params, content, style, valid):
    zc, zs, _, _ = M.encode_pair(params["autoencoder"], content, style, cfg=CFG)
    c, s = tokenize(zc, CFG.token_width, CFG.token_stride), tokenize(zs, CFG.token_width, CFG.token_stride)
    return transformer_loss_terms(params["transformer"], c, s, cfg=CFG, train=TransformerTrainConfig(),
                                  style_valid=valid)


def test_loss_unchanged_by_padding():
    params = random_params(1)
    content = smooth_motion(5, 1, 64, 39)
    style = smooth_motion(6, 1, 96, 39)  # a multiple of 8 frames: every token of the exact clip is whole
    n_real, n_pad = int(tdata.style_token_count(96, MODE)), int(tdata.style_token_count(160, MODE))
    exact = _terms(params, content, style, jnp.ones((1, n_real), bool))
    padded = jnp.pad(style, ((0, 0), (0, 64), (0, 0)), mode="edge")
    masked = _terms(params, content, padded, jnp.arange(n_pad)[None] < n_real)
    for k in ("identity", "cyclic", "structure", "appearance", "loss"):
        np.testing.assert_allclose(masked[k], exact[k], rtol=1e-4, atol=1e-5, err_msg=k)
    unmasked = _terms(params, content, padded, jnp.ones((1, n_pad), bool))  # same compilation as `masked`
    assert abs(float(unmasked["loss"][0] - exact["loss"][0])) > 1e-4  # the mask is what makes them equal


@pytest.mark.slow  # one compilation of the whole training step (~30 s of CPU)
def test_train_step_takes_the_masked_batch():
    data = _body([70, 96, 130, 150])
    batch = tdata.transformer_batch(data, MODE, seed=0, step=0)
    params = random_params(2)
    import optax

    tx = optax.adam(1e-3)
    state = create_transformer_state(MODE, jax.tree_util.tree_map(jnp.array, params["transformer"]), tx)
    step = jax.jit(make_transformer_train_step(MODE, tx, params["autoencoder"]))
    state, metrics = step(state, {k: jnp.asarray(v) for k, v in batch.items()}, jax.random.key(0))
    assert np.isfinite(float(metrics["loss"])) and int(state.step) == 1


def test_style_tokens_option_is_checked():
    with pytest.raises(ValueError, match="style_tokens"):
        TransformerTrainConfig(style_tokens="whole")
    with pytest.raises(ValueError):
        TransformerTrainConfig(style_bucket=0.5)

"""TGST transfer on arrays: every method's shapes, jit == eager without retracing, short clips, the authors'
variant, soft-swap weights and options, and the transformer's training step."""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxgest.tgst import model as tmodel
from jaxgest.tgst.model import transfer_arrays
from jaxgest.tgst.steps import create_transformer_state, make_transformer_train_step
from jaxgest.tgst.tokens import ClipTooShortError

from tgst_testing import CFG, FULL, random_params, smooth_motion


@pytest.fixture(scope="module")
def params():
    return random_params()


def test_all_methods_run_with_right_shapes(params):
    content, style = smooth_motion(1, 2, 50, 39), smooth_motion(2, 2, 70, 39)
    methods = tmodel.METHODS

    @jax.jit  # one compilation for the five methods
    def run_all(params, content, style):
        return {m: transfer_arrays(params, content, style, cfg=CFG, method=m) for m in methods}

    results = run_all(params, content, style)
    for method, (up, lo, aux) in results.items():
        assert up.shape == (2, 50, 39) and lo.shape == (2, 50, 24), method
        assert bool(jnp.isfinite(up).all() & jnp.isfinite(lo).all()), method
        # 50 frames + 16 edge frames at both ends -> padded 96 -> 24 latent frames
        assert aux["content_latents"].shape == (2, 24, 16)
    recon = jax.jit(tmodel.reconstruct, static_argnames="cfg")(params["autoencoder"], content, cfg=CFG)
    np.testing.assert_allclose(np.asarray(results["autoencoder"][0]), np.asarray(recon[0]), atol=1e-6)
    np.testing.assert_allclose(np.asarray(results["autoencoder"][1]), np.asarray(recon[1]), atol=1e-6)
    assert not np.allclose(np.asarray(results["soft"][0]), np.asarray(results["adain"][0]))
    with pytest.raises(ValueError, match="unknown transfer method"):
        transfer_arrays(params, content, style, cfg=CFG, method="magic")


@pytest.fixture(scope="module")
def traced_soft():
    @jax.jit
    @chex.assert_max_traces(n=1)
    def fn(params, content, style):
        return transfer_arrays(params, content, style, cfg=CFG, method="soft")

    return fn


def test_jit_equals_eager_and_no_retrace(params, traced_soft):
    content, style = smooth_motion(3, 1, 40, 39), smooth_motion(4, 1, 33, 39)
    up_j, lo_j, aux_j = traced_soft(params, content, style)
    up_e, lo_e, _ = transfer_arrays(params, content, style, cfg=CFG, method="soft")  # op by op
    np.testing.assert_allclose(np.asarray(up_j), np.asarray(up_e), atol=1e-5)
    np.testing.assert_allclose(np.asarray(lo_j), np.asarray(lo_e), atol=1e-5)
    w = aux_j["swap_weights"]  # soft swap weights: rows on the simplex over the style tokens
    np.testing.assert_allclose(np.asarray(w.sum(-1)), 1.0, rtol=1e-5)
    traced_soft(params, content + 0.1, style - 0.1)  # same shapes: must not retrace
    with pytest.raises(AssertionError):
        traced_soft(params, smooth_motion(5, 1, 48, 39), style)  # new shape retraces (the guard works)


def test_short_clip_error(params):
    with pytest.raises(ClipTooShortError, match="15 frames"):
        transfer_arrays(params, jnp.zeros((1, 15, 39)), jnp.zeros((1, 32, 39)), cfg=CFG)
    with pytest.raises(ClipTooShortError):
        transfer_arrays(params, jnp.zeros((1, 32, 39)), jnp.zeros((1, 8, 39)), cfg=CFG)


def test_authors_variant_runs(params):
    acfg = dataclasses.replace(CFG, transformer=dataclasses.replace(CFG.transformer, variant="authors"))
    content = jnp.concatenate([smooth_motion(6, 1, 32, 39)] * 2)  # the same clip twice
    up, lo, _ = jax.jit(transfer_arrays, static_argnames=("cfg", "method"))(
        params, content, smooth_motion(7, 2, 40, 39), cfg=acfg)
    assert up.shape == (2, 32, 39) and bool(jnp.isfinite(up).all())


def test_swap_weights_rows_on_simplex_and_match_transfer(params):
    content, style = smooth_motion(13, 2, 50, 39), smooth_motion(14, 2, 70, 39)
    fn = jax.jit(tmodel.swap_weights, static_argnames="cfg")
    w = np.asarray(fn(params, content, style, cfg=CFG))
    n_c = tmodel.num_tokens(-(-50 // 4))  # tokens of the real content frames only
    n_s = tmodel.num_tokens(-(-70 // 4))
    assert w.shape == (2, n_c, n_s)
    np.testing.assert_allclose(w.sum(-1), 1.0, rtol=1e-5)
    _, _, aux = jax.jit(transfer_arrays, static_argnames=("cfg", "method"))(params, content, style, cfg=CFG)
    np.testing.assert_allclose(np.asarray(aux["swap_weights"])[:, 2:2 + n_c], w, atol=1e-6)


@pytest.mark.parametrize("similarity,positions", [("dot", "none"), ("scaled", "index"), ("scaled", "none")])
def test_swap_options_run_and_keep_the_simplex(params, similarity, positions):
    cfg = dataclasses.replace(CFG, swap_similarity=similarity,
                              transformer=dataclasses.replace(CFG.transformer, token_positions=positions))
    content, style = smooth_motion(15, 1, 40, 39), smooth_motion(16, 1, 40, 39)
    w = np.asarray(jax.jit(tmodel.swap_weights, static_argnames="cfg")(params, content, style, cfg=cfg))
    np.testing.assert_allclose(w.sum(-1), 1.0, rtol=1e-5)
    if similarity == "scaled":  # bounded logits: no row can be one-hot from untrained random tokens
        assert w.max() < 0.99
    with pytest.raises(ValueError, match="swap_similarity"):
        dataclasses.replace(CFG, swap_similarity="cosine")


def test_transformer_loss_decreases(params):
    tx = optax.adam(1e-3)
    state = create_transformer_state(FULL, jax.tree_util.tree_map(jnp.copy, params["transformer"]), tx)
    step = jax.jit(make_transformer_train_step(FULL, tx, params["autoencoder"]), donate_argnums=(0,))
    batch = {"content": smooth_motion(12, 2, 64, 39), "style": smooth_motion(13, 2, 48, 39)}
    key = jax.random.key(0)
    state, first = step(state, batch, key)
    for _ in range(29):
        state, metrics = step(state, batch, key)
    assert set(metrics) == {"loss", "identity", "cyclic", "structure", "appearance"}
    assert all(bool(jnp.isfinite(v)) for v in metrics.values())
    assert float(metrics["loss"]) < 0.8 * float(first["loss"])

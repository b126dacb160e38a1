"""Tokens, swaps, losses and baselines of TGST (paper 000): invariants and properties."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.runtime.errors import DataError
from jaxgest.tgst import baselines, losses, swap, tokens

SETTINGS = settings(max_examples=25, deadline=None)


def _normal(seed, shape, scale=1.0):
    """Seeded float32 normal data (NumPy: no per-shape compilation)."""
    return jnp.asarray(scale * np.random.default_rng(seed).normal(size=shape), jnp.float32)


# ---------------------------------------------------------------- tokens (eq. 1)

_tokenize = jax.jit(lambda z: tokens.tokenize(z, 4, 2))
_detokenize = jax.jit(lambda g, n: tokens.detokenize(g, n, 4, 2), static_argnums=1)


@SETTINGS
@given(length=st.integers(4, 70), seed=st.integers(0, 2**16))
def test_tokenize_detokenize_identity(length, seed):
    z = np.random.default_rng(seed).normal(size=(2, length, 3)).astype(np.float32)
    g = _tokenize(jnp.asarray(z))
    assert g.shape == (2, tokens.num_tokens(length, w=4, h=2), 12)
    assert g.shape[1] == -(-length // 2) - 1
    np.testing.assert_allclose(np.asarray(_detokenize(g, length)), z, rtol=1e-6, atol=1e-6)


def test_tokens_are_half_overlapping_windows():
    z = jnp.arange(8 * 2, dtype=jnp.float32).reshape(1, 8, 2)
    g = tokens.tokenize(z, 4, 2)
    assert g.shape == (1, 3, 8)  # floor(8 / 2) - 1
    np.testing.assert_array_equal(g[0, 1], z[0, 2:6].reshape(-1))


def test_detokenize_crossfades_linearly():
    # Two tokens: constant 0 then constant 3 -> the overlap ramps 0 -> 3 at 1/3, 2/3.
    g = jnp.concatenate([jnp.zeros((1, 1, 4)), 3 * jnp.ones((1, 1, 4))], axis=1)
    z = tokens.detokenize(g, 6, 4, 2)[0, :, 0]
    np.testing.assert_allclose(np.asarray(z), [0, 0, 1, 2, 3, 3], atol=1e-6)


def test_short_clip_error_is_data_and_value_error():
    with pytest.raises(tokens.ClipTooShortError, match="15 frames") as info:
        tokens.pad_frames(jnp.zeros((1, 15, 39)), 16)
    assert isinstance(info.value, DataError) and isinstance(info.value, ValueError)
    with pytest.raises(DataError):
        tokens.tokenize(jnp.zeros((1, 3, 16)))


def test_pad_and_trim_frames():
    x = _normal(0, (2, 17, 3))
    p = tokens.pad_frames(x, 16)
    assert p.shape == (2, 32, 3)
    np.testing.assert_array_equal(p[:, 17:], jnp.broadcast_to(x[:, -1:], (2, 15, 3)))
    np.testing.assert_array_equal(tokens.trim_frames(p, 17), x)


# ---------------------------------------------------------------- swaps (eqs. 4, 19)

_soft_weights = jax.jit(swap.soft_swap_weights)
_soft_swap = jax.jit(swap.soft_swap)


@SETTINGS
@given(seed=st.integers(0, 2**16), scale=st.floats(0.1, 10.0))
def test_soft_swap_is_in_convex_hull_of_style_tokens(seed, scale):
    rng = np.random.default_rng(seed)
    dec = jnp.asarray(scale * rng.normal(size=(2, 5, 8)), jnp.float32)
    enc_s = jnp.asarray(scale * rng.normal(size=(2, 7, 8)), jnp.float32)
    style = jnp.asarray(rng.normal(size=(2, 6, 8)), jnp.float32)
    w = _soft_weights(dec, enc_s)
    assert w.shape == (2, 5, 6)
    assert bool(jnp.all(w >= 0))
    np.testing.assert_allclose(np.asarray(w.sum(-1)), 1.0, rtol=1e-5)
    out = _soft_swap(dec, enc_s, style)
    lo, hi = style.min(axis=1, keepdims=True), style.max(axis=1, keepdims=True)
    assert bool(jnp.all(out >= lo - 1e-5)) and bool(jnp.all(out <= hi + 1e-5))


def test_soft_swap_excludes_cls():
    dec = jnp.ones((1, 2, 4))
    enc_s = jnp.concatenate([100 * jnp.ones((1, 1, 4)), jnp.zeros((1, 3, 4))], axis=1)  # CLS would win
    np.testing.assert_allclose(np.asarray(swap.soft_swap_weights(dec, enc_s)), 1 / 3, rtol=1e-6)


def test_hard_swap_is_soft_swap_at_zero_temperature():
    dec = _normal(3, (2, 5, 8))
    enc_s = _normal(4, (2, 7, 8))
    style = _normal(5, (2, 6, 8))
    hard = swap.hard_swap(dec, enc_s, style)
    soft = swap.apply_swap(swap.soft_swap_weights(dec, enc_s, temperature=1e-4), style)
    np.testing.assert_allclose(np.asarray(soft), np.asarray(hard), atol=1e-5)
    # every hard-swapped token is one of the style tokens
    d = jnp.abs(hard[:, :, None, :] - style[:, None, :, :]).sum(-1).min(-1)
    assert float(d.max()) == 0.0


# ---------------------------------------------------------------- losses (eqs. 5-12)

@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_nearest_token_weights_pick_the_nearest_style_token(seed):
    rng = np.random.default_rng(seed)
    style = rng.normal(size=(1, 6, 8)).astype(np.float32)
    pick = rng.integers(0, 6, size=4)
    content = style[:, pick] + 0.01 * rng.normal(size=(1, 4, 8)).astype(np.float32)
    hard = np.asarray(swap.nearest_token_weights(jnp.asarray(content), jnp.asarray(style)))
    np.testing.assert_array_equal(hard[0].argmax(-1), pick)
    np.testing.assert_allclose(hard.sum(-1), 1.0)
    np.testing.assert_allclose(np.asarray(swap.apply_swap(hard, style)), style[:, pick], atol=1e-6)
    soft = np.asarray(swap.nearest_token_weights(jnp.asarray(content), jnp.asarray(style), temperature=1.0))
    np.testing.assert_allclose(soft.sum(-1), 1.0, rtol=1e-5)
    assert (soft[0].argmax(-1) == pick).all()
    flat = np.asarray(swap.nearest_token_weights(jnp.asarray(content), jnp.asarray(style), temperature=1e9))
    np.testing.assert_allclose(flat, 1 / 6, rtol=1e-3)  # a huge temperature blends every style token evenly
    valid = np.ones((1, 6), bool)
    valid[0, pick[0]] = False  # the nearest token of content 0 is padding: never chosen
    masked = np.asarray(swap.nearest_token_weights(jnp.asarray(content), jnp.asarray(style), style_valid=valid))
    assert masked[0, 0, pick[0]] == 0.0 and masked[0, 0].sum() == 1.0


def test_token_norm_is_mean_per_token_l2():
    x = jnp.asarray([[[3.0, 4.0], [0.0, 0.0]]])
    np.testing.assert_allclose(np.asarray(losses.token_norm(x)), [2.5])


def test_identity_and_cyclic_zero_when_tokens_unchanged():
    gc, gs = _normal(0, (2, 5, 8)), _normal(1, (2, 4, 8))
    np.testing.assert_array_equal(np.asarray(losses.identity_loss(gc, gc, gs, gs)), 0.0)
    np.testing.assert_array_equal(np.asarray(losses.cyclic_loss(gc, gc)), 0.0)
    assert bool(jnp.all(losses.identity_loss(gc + 1, gc, gs, gs) > 0))
    g = jax.grad(lambda a: losses.identity_loss(a, gc, gs, gs).sum())(gc)
    assert bool(jnp.all(jnp.isfinite(g)))  # safe norm at exactly zero


def test_structure_matrix_is_cosine_self_similarity():
    k = _normal(2, (2, 6, 8))
    m = losses.structure_matrix(k)
    np.testing.assert_allclose(np.asarray(jnp.diagonal(m, axis1=1, axis2=2)), 1.0, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(m), np.asarray(jnp.swapaxes(m, 1, 2)), atol=1e-6)
    assert float(jnp.abs(m).max()) <= 1 + 1e-5


@SETTINGS
@given(seed=st.integers(0, 2**16))
def test_structure_loss_zero_and_invariant_to_positive_key_scaling(seed):
    k = _normal(seed, (2, 7, 8))
    scale = jnp.exp(_normal(seed + 1, (2, 7, 1)))
    np.testing.assert_allclose(np.asarray(losses.structure_loss(k, k)), 0.0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(losses.structure_loss(k, k * scale)), 0.0, atol=1e-4)
    assert bool(jnp.all(losses.structure_loss(k, _normal(seed + 2, (2, 7, 8))) > 0))


def test_appearance_loss_symmetric_l2():
    a, b = _normal(0, (3, 8)), _normal(1, (3, 8))
    ab, ba = losses.appearance_loss(a, b), losses.appearance_loss(b, a)
    np.testing.assert_allclose(np.asarray(ab), np.asarray(ba))
    np.testing.assert_allclose(np.asarray(losses.appearance_loss(a, b)),
                               np.linalg.norm(np.asarray(a - b), axis=-1), rtol=1e-5)


def test_total_loss_weights_and_switches():
    i, c, s, a = (jnp.asarray([v]) for v in (1.0, 2.0, 4.0, 8.0))
    np.testing.assert_allclose(np.asarray(losses.total_transformer_loss(i, c, s, a)), [15.0])
    nan = jnp.asarray([jnp.nan])
    out = losses.total_transformer_loss(i, c, s, nan, lambda_cyclic=0.5, use_appearance=False)
    np.testing.assert_allclose(np.asarray(out), [6.0])
    with pytest.raises(ValueError):
        losses.total_transformer_loss(i, c, s, a, use_identity=False, use_cyclic=False, use_structure=False,
                                      use_appearance=False)


# ---------------------------------------------------------------- baselines (eqs. 17, 18)

def test_adain_output_has_style_statistics():
    zc, zs = _normal(0, (2, 20, 16)), 2.0 + 3.0 * _normal(1, (2, 12, 16))
    out = jax.jit(baselines.adain_latents)(zc, zs)
    np.testing.assert_allclose(np.asarray(out.mean(1)), np.asarray(zs.mean(1)), atol=1e-4)
    np.testing.assert_allclose(np.asarray(out.std(1)), np.asarray(zs.std(1)), rtol=1e-4)
    # statistics over valid frames only
    out_v = jax.jit(baselines.adain_latents, static_argnames=("content_valid", "style_valid"))(
        zc, zs, content_valid=15, style_valid=9)
    np.testing.assert_allclose(np.asarray(out_v[:, :15].std(1)), np.asarray(zs[:, :9].std(1)), rtol=1e-4)


def test_cosine_argmax_swap_picks_most_similar_style_token():
    style = _normal(0, (1, 5, 8))
    content = 2.5 * style[:, ::-1]  # scaled copies: cosine picks them regardless of norm
    np.testing.assert_allclose(np.asarray(baselines.cosine_argmax_swap(content, style)),
                               np.asarray(style[:, ::-1]), rtol=1e-6)


def test_avatarnet_recolours_with_style_statistics():
    zs = 1.0 + 2.0 * _normal(1, (2, 16, 4))
    avatar = jax.jit(baselines.avatarnet_swap)
    out = avatar(5.0 * zs - 3.0, zs)  # content = affine copy of style -> whitened equal
    np.testing.assert_allclose(np.asarray(out), np.asarray(zs), atol=1e-4)
    assert jax.eval_shape(avatar, jnp.zeros((2, 10, 4)), zs).shape == (2, 10, 4)


# ---------------------------------------------------------------- reconstruction baselines of the autoencoder

def test_block_pca_exact_at_full_rank_and_lossy_below():
    rng = np.random.default_rng(0)
    clips = [rng.normal(size=(n, 6)).astype(np.float32) for n in (40, 33, 57)]
    full = baselines.block_pca_fit(clips, components=24, frames=4)  # 4 frames x 6 channels = 24 numbers
    x = rng.normal(size=(21, 6)).astype(np.float32)
    np.testing.assert_allclose(baselines.block_pca_reconstruct(full, x), x, atol=1e-4)
    low = baselines.block_pca_fit(clips, components=3, frames=4)
    assert baselines.block_pca_reconstruct(low, x).shape == (21, 6)
    assert not np.allclose(baselines.block_pca_reconstruct(low, x), x, atol=1e-2)


def test_mean_pose_and_per_joint_angles():
    a = np.zeros((5, 6), np.float32)
    a[:, 2] = 0.2  # joint 0: 0.2 rad about z
    b = a.copy()
    b[:, 2] = 0.6
    b[:, 3] = np.pi - 0.05  # joint 1 near pi about x: its exp-map flips to the antipode in a
    a[:, 3] = -(np.pi - 0.05)
    mean = baselines.mean_pose_fit([a, b])
    np.testing.assert_allclose(mean[:3], [0, 0, 0.4], atol=1e-5)  # rotation mean about one axis
    assert abs(abs(mean[3]) - np.pi) < 1e-4 and np.allclose(mean[4:], 0, atol=1e-5)  # not the channel mean 0
    x = np.zeros((4, 6), np.float32)
    x[:, 3] = 0.5  # joint 1 turned by 0.5 rad about x; joint 0 at the identity
    err = baselines.per_joint_angle_deg(np.zeros(6, np.float32), x)
    np.testing.assert_allclose(err, [0.0, np.degrees(0.5)], atol=1e-3)

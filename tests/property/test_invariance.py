"""Invariance properties (hypothesis, small example counts):

* TGST soft swap (eq. 4): the transferred tokens do not change when the style tokens are permuted (their
  encodings permuted the same way, the CLS row left first) -- for the swap itself with any similarity, and for
  the whole token transfer of a random-init transformer without positions and with a band covering every
  token (with index positions the order matters: the control);
* TGST transfer on arrays: a batch of clips gives, clip for clip, the output of one clip at a time;
* ZeroEGGS reconstruction terms (eq. 2): unchanged when the predicted and the target roots move together by
  one rigid motion -- any translation, and rotations about the vertical (Y) axis by multiples of 90 degrees
  (the terms are mean ABSOLUTE errors of vector components, invariant to rotations that permute and negate
  the X/Z components only); moving the predicted root alone changes the world terms (the control).

References: Kuriyama et al. 2022, eq. 4, Fig. 2; Ghorbani et al. 2023, eq. 2.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.motion import rotations as R
from jaxgest.tgst import model as tmodel
from jaxgest.tgst import swap
from jaxgest.zeggs import losses as zlosses
from jaxgest.zeggs.config import preset as zeggs_preset

from tgst_testing import CFG, TINY, random_like, random_params, smooth_motion

SETTINGS = settings(max_examples=12, deadline=None)
NC, NS, D = 5, 7, 64  # content tokens, style tokens, token width (tiny preset)


def _normal(seed, shape, scale=1.0):
    return jnp.asarray(scale * np.random.default_rng(seed).normal(size=shape), jnp.float32)


def _permute_style(encoded_style, style_tokens, perm):
    """Style tokens in another order: their encodings permuted alike, CLS (row 0) kept first."""
    perm = np.asarray(perm)
    return (jnp.concatenate([encoded_style[:, :1], encoded_style[:, 1 + perm]], axis=1),
            style_tokens[:, perm])


# ----- TGST: soft swap under a permutation of the style tokens ---------------------------------------------

@functools.partial(jax.jit, static_argnames="similarity")
def _swap(decoded, encoded_style, style_tokens, similarity):
    return swap.apply_swap(swap.soft_swap_weights(decoded, encoded_style, similarity=similarity), style_tokens)


@SETTINGS
@given(seed=st.integers(0, 2**16), perm=st.permutations(range(NS)), similarity=st.sampled_from(swap.SIMILARITIES))
def test_soft_swap_is_unchanged_by_a_permutation_of_the_style_tokens(seed, perm, similarity):
    decoded, enc_s, tokens = _normal(seed, (2, NC, D)), _normal(seed + 1, (2, 1 + NS, D)), _normal(seed + 2, (2, NS, D))
    out = _swap(decoded, enc_s, tokens, similarity)
    out_perm = _swap(decoded, *_permute_style(enc_s, tokens, perm), similarity)
    np.testing.assert_allclose(np.asarray(out_perm), np.asarray(out), rtol=1e-5, atol=1e-5)
    # CLS aside: the CLS row takes no part in the swap
    np.testing.assert_allclose(np.asarray(_swap(decoded, enc_s.at[:, 0].add(3.0), tokens, similarity)),
                               np.asarray(out), rtol=1e-6, atol=1e-6)
    # and the swap does depend on which encoding goes with which token (the property is not vacuous)
    if list(perm) != sorted(perm):
        shuffled = _swap(decoded, enc_s, tokens[:, np.asarray(perm)], similarity)
        assert not np.allclose(np.asarray(shuffled), np.asarray(out), atol=1e-5)


def _transformer_cfg(positions):
    """Tiny TGST whose encoder band covers every token; ``positions``: "none" or "index"."""
    return dataclasses.replace(TINY.model, transformer=dataclasses.replace(
        TINY.model.transformer, token_positions=positions, omega=16, block_size=16, attention_impl="dense"))


@functools.lru_cache(maxsize=None)
def _transformer_params():
    cfg = _transformer_cfg("none")
    return random_like(jax.eval_shape(lambda k: tmodel.init_params(cfg, k), jax.random.key(0)),
                       seed=3)["transformer"]


@functools.partial(jax.jit, static_argnames="cfg")
def _transfer_tokens(params, content, style, cfg):
    return tmodel.transfer_tokens(params, content, style, cfg=cfg)[0]


@SETTINGS
@given(seed=st.integers(0, 2**16), perm=st.permutations(range(NS)))
def test_token_transfer_is_unchanged_by_a_permutation_of_the_style_tokens(seed, perm):
    """T_E (no positions, full band) is permutation-equivariant and T_D's cross-attention and the swap are
    invariant to the order of the style: the transferred tokens are the same."""
    params, cfg = _transformer_params(), _transformer_cfg("none")
    content, style = _normal(seed, (1, NC, D)), _normal(seed + 1, (1, NS, D))
    out = _transfer_tokens(params, content, style, cfg)
    out_perm = _transfer_tokens(params, content, style[:, np.asarray(perm)], cfg)
    np.testing.assert_allclose(np.asarray(out_perm), np.asarray(out), rtol=1e-4, atol=1e-5)


def test_token_transfer_with_index_positions_depends_on_the_style_order():
    """Control: with sinusoidal index positions (eq. 2) the encoder sees the order, so a reversal changes the
    output -- the invariance above is a property of the position-free model, not of the test."""
    params, cfg = _transformer_params(), _transformer_cfg("index")
    content, style = _normal(0, (1, NC, D)), _normal(1, (1, NS, D))
    out = _transfer_tokens(params, content, style, cfg)
    out_rev = _transfer_tokens(params, content, style[:, ::-1], cfg)
    assert not np.allclose(np.asarray(out_rev), np.asarray(out), atol=1e-4)


# ----- TGST: batched transfer == one clip at a time --------------------------------------------------------

_transfer = jax.jit(tmodel.transfer_arrays, static_argnames=("cfg", "method"))


@SETTINGS
@given(seed=st.integers(0, 2**16), shared_style=st.booleans())
def test_batched_transfer_equals_per_clip_transfer(seed, shared_style):
    """Content ``(3, 40, 39)`` in the style of ``(3 | 1, 36, 39)``: row b of the batched output is the transfer
    of clip b alone (a shared style clip is broadcast)."""
    params = random_params()
    content = smooth_motion(seed, 3, 40, 39)
    style = smooth_motion(seed + 1, 1 if shared_style else 3, 36, 39)
    up, lo, _ = _transfer(params, content, style, cfg=CFG, method="soft")
    for b in range(3):
        s = style if shared_style else style[b:b + 1]
        up_b, lo_b, _ = _transfer(params, content[b:b + 1], s, cfg=CFG, method="soft")
        np.testing.assert_allclose(np.asarray(up[b]), np.asarray(up_b[0]), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(np.asarray(lo[b]), np.asarray(lo_b[0]), rtol=1e-5, atol=1e-5)
    if not shared_style:  # the clips differ, so equal rows would mean the batch was collapsed
        assert not np.allclose(np.asarray(up[0]), np.asarray(up[1]), atol=1e-4)


# ----- ZeroEGGS: world-space terms when both roots move together -------------------------------------------

ZCFG = zeggs_preset("tiny").model  # 5 joints
#: a 5-joint rig (root, spine, neck, two arms) for the FK variant of the position terms
ZCFG_FK = ZCFG.replace(fk_parents=(-1, 0, 1, 2, 2), fk_translated=(0,),
                       fk_offsets=(0, 0, 0, 0, 10, 0, 0, 12, 0, 8, 2, 0, -8, 2, 0))


def _unit_quats(rng, shape):
    q = rng.normal(size=shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _zeggs_inputs(seed, batch=2, frames=6):
    rng = np.random.default_rng(seed)
    f32 = functools.partial(jnp.asarray, dtype=jnp.float32)
    pose = lambda: f32(rng.normal(size=(batch, frames, ZCFG.pose_dim)) * 5.0)  # noqa: E731
    return (pose(), f32(rng.normal(size=(batch, frames, 3)) * 50.0), f32(_unit_quats(rng, (batch, frames))),
            pose(), f32(rng.normal(size=(batch, frames, 3)) * 50.0), f32(_unit_quats(rng, (batch, frames))))


def _move(root_position, root_rotation, quarter_turns, translation):
    """Both roots' rigid motion: rotate about Y by ``quarter_turns`` x 90 degrees, then translate."""
    half = quarter_turns * np.pi / 4
    q = np.broadcast_to(np.float32([np.cos(half), 0.0, np.sin(half), 0.0]), root_rotation.shape)
    shift = np.broadcast_to(np.float32(translation), root_position.shape)
    return _rigid(root_position, root_rotation, jnp.asarray(q), jnp.asarray(shift))


@jax.jit
def _rigid(root_position, root_rotation, q, shift):
    return R.quat_rotate(q, root_position) + shift, R.quat_mul(q, root_rotation)


@functools.partial(jax.jit, static_argnames="cfg")
def _terms(pp, pr, pq, tp, tr, tq, cfg):
    return zlosses.reconstruction_terms(pp, pr, pq, tp, tr, tq, cfg=cfg)


@SETTINGS
@given(seed=st.integers(0, 2**16), quarter_turns=st.integers(0, 3),
       translation=st.lists(st.floats(-300, 300, width=32), min_size=3, max_size=3), rig=st.booleans())
def test_zeggs_terms_unchanged_when_both_roots_move_together(seed, quarter_turns, translation, rig):
    cfg = ZCFG_FK if rig else ZCFG
    pp, pr, pq, tp, tr, tq = _zeggs_inputs(seed)
    base = _terms(pp, pr, pq, tp, tr, tq, cfg)
    moved = _terms(pp, *_move(pr, pq, quarter_turns, translation), tp, *_move(tr, tq, quarter_turns, translation),
                   cfg)
    assert set(moved) == set(base)
    for k in base:  # world, local and root terms alike
        np.testing.assert_allclose(np.asarray(moved[k]), np.asarray(base[k]), rtol=1e-4, atol=1e-3, err_msg=k)


@pytest.mark.parametrize("rig", [False, True])
def test_zeggs_world_terms_see_a_root_moved_alone(rig):
    """Control: translating (or turning) only the predicted root changes the world terms, not the local ones."""
    cfg = ZCFG_FK if rig else ZCFG
    pp, pr, pq, tp, tr, tq = _zeggs_inputs(0)
    base = _terms(pp, pr, pq, tp, tr, tq, cfg)
    shifted = _terms(pp, *_move(pr, pq, 0, [30.0, 0.0, -20.0]), tp, tr, tq, cfg)
    turned = _terms(pp, *_move(pr, pq, 1, [0.0, 0.0, 0.0]), tp, tr, tq, cfg)
    for k in ("world_position", "root_position"):
        assert not np.allclose(np.asarray(shifted[k]), np.asarray(base[k]), rtol=1e-3), k
    for k in ("world_position", "world_rotation", "world_velocity", "world_angular", "facing", "root_rotation"):
        assert not np.allclose(np.asarray(turned[k]), np.asarray(base[k]), rtol=1e-3), k
    for k in ("local_position", "local_rotation", "local_velocity", "local_angular"):
        np.testing.assert_allclose(np.asarray(shifted[k]), np.asarray(base[k]), rtol=1e-6, err_msg=k)
        np.testing.assert_allclose(np.asarray(turned[k]), np.asarray(base[k]), rtol=1e-6, err_msg=k)

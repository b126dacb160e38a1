"""TGST style transformer encoder: the banded self-attention (blockwise == dense masked reference, the band
masks of both variants, tokens beyond omega have no influence)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.tgst import transformer as T
from jaxgest.tgst.transformer import (StyleTransformerEncoder, band_mask, blockwise_banded_attention,
                                      dense_banded_attention)

from tgst_testing import TINY, normal, random_like


@pytest.mark.parametrize("variant", ["paper", "authors"])
@pytest.mark.parametrize("n", [1, 9, 23])
def test_blockwise_equals_dense(variant, n):
    q, k, v = (normal(s, (2, n + 1, 8)) for s in (1, 2, 3))

    @jax.jit
    def both(q, k, v):
        dense, _ = dense_banded_attention(q, k, v, omega=3, variant=variant)
        return dense, blockwise_banded_attention(q, k, v, omega=3, variant=variant, block_size=4)

    dense, block = both(q, k, v)
    np.testing.assert_allclose(np.asarray(block), np.asarray(dense), atol=1e-5)


def test_band_masks():
    m = band_mask(8, omega=2, variant="paper")
    assert m[0].all() and m[:, 0].all()
    assert m[5, 3] and m[5, 7] and not m[5, 2] and not m[5, 8]
    a = band_mask(8, omega=2, variant="authors")
    assert a[0].all() and a[2, 0] and not a[3, 0]  # CLS visible to gesture rows i <= omega only
    assert a[5, 3] and a[5, 6] and not a[5, 7] and not a[5, 2]  # i - omega <= j < i + omega


@pytest.fixture(scope="module")
def encoders():
    """Jitted encoders (blockwise, dense) sharing one set of parameters; omega = 3, 24 tokens."""
    out = {}
    tok = normal(0, (1, 24, 64))
    variables = None
    for impl in ("blockwise", "dense"):
        tcfg = dataclasses.replace(TINY.model.transformer, omega=3, block_size=4, attention_impl=impl)
        enc = StyleTransformerEncoder(tcfg)
        variables = variables or random_like(jax.eval_shape(enc.init, jax.random.key(1), tok), seed=1)
        out[impl] = jax.jit(lambda t, enc=enc: enc.apply(variables, t))
    return out, tok


def test_encoder_blockwise_equals_dense(encoders):
    fns, tok = encoders
    (yb, auxb), (yd, auxd) = fns["blockwise"](tok), fns["dense"](tok)
    np.testing.assert_allclose(np.asarray(yb), np.asarray(yd), atol=1e-5)
    np.testing.assert_allclose(np.asarray(auxb["keys"]), np.asarray(auxd["keys"]), atol=1e-6)
    assert auxd["attention"].shape == (1, 25, 25) and "attention" not in auxb


@settings(max_examples=15, deadline=None)
@given(i=st.integers(0, 23), j=st.integers(0, 23), impl=st.sampled_from(["blockwise", "dense"]))
def test_tokens_beyond_omega_have_no_influence(encoders, i, j, impl):
    fns, tok = encoders
    y0, aux0 = fns[impl](tok)
    y1, aux1 = fns[impl](tok.at[0, j].add(normal(99, (64,))))  # not constant: LayerNorm would remove it
    changed = not np.allclose(np.asarray(y0[0, 1 + i]), np.asarray(y1[0, 1 + i]), atol=1e-5)
    assert changed == (abs(i - j) <= 3)
    assert not np.allclose(np.asarray(aux0["cls"]), np.asarray(aux1["cls"]))  # CLS attends to all


@pytest.mark.parametrize("n", [5, 12])
def test_short_sequences_take_the_dense_form_with_the_same_output(monkeypatch, n):
    """Up to SHORT_BLOCKS blocks the blockwise encoder computes the dense masked form (less work there);
    its output, keys and CLS equal those of the blockwise computation (forced by SHORT_BLOCKS = 0)."""
    tcfg = dataclasses.replace(TINY.model.transformer, omega=3, block_size=4, attention_impl="blockwise")
    enc = StyleTransformerEncoder(tcfg)
    tok = normal(3, (2, n, 64))
    valid = jnp.arange(n)[None] < jnp.array([[n], [n - 2]])
    variables = random_like(jax.eval_shape(enc.init, jax.random.key(1), tok), seed=2)
    assert n <= T.SHORT_BLOCKS * tcfg.block_size
    short = enc.apply(variables, tok, valid)
    monkeypatch.setattr(T, "SHORT_BLOCKS", 0)
    blocks = enc.apply(variables, tok, valid)
    np.testing.assert_allclose(np.asarray(short[0][0]), np.asarray(blocks[0][0]), atol=1e-5)
    np.testing.assert_allclose(np.asarray(short[0][1, :n - 1]), np.asarray(blocks[0][1, :n - 1]), atol=1e-5)
    np.testing.assert_allclose(np.asarray(short[1]["cls"]), np.asarray(blocks[1]["cls"]), atol=1e-5)
    assert "attention" not in short[1]

"""The time-coherent swap (not in the paper): constant-rate paths through the style tokens, and how far the
swap's choices step from one content token to the next."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgest.runtime.errors import DataError
from jaxgest.tgst import swap
from jaxgest.tgst.batched import argmax_steps, swap_diagnostics


def planted(nc, ns, start, rate, noise=0.0, seed=0):
    """Scores (1, nc, ns) peaked on the path round(start + rate n), with optional noise."""
    path = np.minimum(np.round(start + rate * np.arange(nc)).astype(int), ns - 1)
    scores = -np.abs(np.arange(ns)[None, :] - path[:, None]).astype(np.float32)
    scores += noise * np.random.default_rng(seed).standard_normal(scores.shape).astype(np.float32)
    return jnp.asarray(scores)[None], path


@pytest.mark.parametrize("start,rate", [(3, 1.5), (0, 1.0), (7, 0.5), (2, 2.0)])
def test_constant_rate_path_recovers_a_planted_path(start, rate):
    scores, path = planted(12, 40, start, rate)
    np.testing.assert_array_equal(np.asarray(swap.constant_rate_path(scores))[0], path)
    # noise that reorders single rows does not break the path (a per-row argmax would jump)
    noisy, _ = planted(12, 40, start, rate, noise=0.8, seed=1)
    got = np.asarray(swap.constant_rate_path(noisy))[0]
    assert np.mean(got == path) >= 0.75
    assert not np.array_equal(np.argmax(np.asarray(noisy)[0], -1), path)  # the noise does move the argmax


def test_constant_rate_path_stays_in_the_style_and_overruns_only_when_nothing_fits():
    scores, _ = planted(10, 30, 29, 1.0)  # the best-scoring start would run 9 tokens past the end
    got = np.asarray(swap.constant_rate_path(scores))[0]
    assert got.max() <= 29 and np.all(np.diff(got) >= 0)
    assert int(np.round(got[0] + 0.5 * 9)) <= 30  # a fitting path: at most one token past the end
    short = np.asarray(swap.constant_rate_path(jnp.zeros((1, 40, 5))))[0]  # no path of 40 fits in 5 tokens
    assert short.min() >= 0 and short.max() <= 4


def test_coherent_weights_are_one_hot_on_a_path_and_skip_padded_tokens():
    key = jax.random.PRNGKey(0)
    c, s = jax.random.normal(key, (2, 9, 8)), jax.random.normal(jax.random.fold_in(key, 1), (2, 21, 8))
    valid = jnp.arange(20)[None, :] < jnp.array([[20], [12]])
    w = np.asarray(jax.jit(swap.coherent_swap_weights)(c, s, style_valid=valid))
    assert w.shape == (2, 9, 20)
    np.testing.assert_array_equal(w.sum(-1), 1.0)
    assert set(np.unique(w)) <= {0.0, 1.0}
    idx = w.argmax(-1)
    assert idx[1].max() < 12  # padded style tokens are never taken when a path fits in the real ones
    steps = np.diff(idx, axis=-1)
    assert np.all(steps >= 0) and np.all(steps <= 2)  # rates 0.5 .. 2.0


def test_argmax_steps_and_swap_diagnostics():
    assert argmax_steps(np.array([0, 1, 2, 2, 5, 3])) == {"one": 0.4, "zero": 0.2, "back": 0.2, "far": 0.2}
    assert np.isnan(argmax_steps(np.array([4]))["one"])
    with pytest.raises(DataError, match="argmax_steps"):
        argmax_steps(np.zeros((2, 2)))
    d = swap_diagnostics(np.eye(6))
    assert d["step_one"] == 1.0 and d["step_zero"] == d["step_back"] == d["step_far"] == 0.0

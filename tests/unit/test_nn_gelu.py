"""jaxgest.nn.gelu_exact: the exact (erf) GELU, equal to jax.nn.gelu(approximate=False) within float32."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.nn import gelu_exact


def test_gelu_exact_is_the_erf_gelu_in_value_and_gradient():
    rng = np.random.default_rng(0)
    x = np.concatenate([np.linspace(-12.0, 12.0, 4001), rng.normal(scale=3.0, size=2000)])
    want = np.array([0.5 * v * (1.0 + math.erf(v / math.sqrt(2.0))) for v in x])  # float64 reference
    got = np.asarray(jax.jit(gelu_exact)(jnp.asarray(x, jnp.float32)), np.float64)
    ref = np.asarray(jax.nn.gelu(jnp.asarray(x, jnp.float32), approximate=False), np.float64)
    assert np.max(np.abs(got - want) / np.maximum(1.0, np.abs(want))) < 2e-6
    assert np.max(np.abs(got - ref)) < 2e-6
    tanh_gelu = np.asarray(jax.nn.gelu(jnp.asarray(x, jnp.float32), approximate=True))
    assert not np.allclose(got, tanh_gelu, atol=1e-4)
    # derivative Phi(x) + x phi(x)
    dwant = np.array([0.5 * (1.0 + math.erf(v / math.sqrt(2.0)))
                      + v * math.exp(-0.5 * v * v) / math.sqrt(2 * math.pi) for v in x])
    dgot = np.asarray(jax.vmap(jax.grad(gelu_exact))(jnp.asarray(x, jnp.float32)), np.float64)
    np.testing.assert_allclose(dgot, dwant, atol=5e-6)
    assert gelu_exact(jnp.ones(3, jnp.bfloat16)).dtype == jnp.bfloat16

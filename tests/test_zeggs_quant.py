"""Weight formats of the ZeroEGGS generator (jaxgest.zeggs.quant): fp32 is the model, bf16 / int8 close."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgest.zeggs import quant as Q


def test_int8_per_channel_quantisation_error_is_within_half_a_step():
    w = jnp.asarray(np.random.default_rng(0).normal(size=(50, 7)) * np.arange(1, 8), jnp.float32)
    qk = Q.quantize_kernel(w, "int8")
    assert qk["w"].dtype == jnp.int8 and qk["scale"].shape == (7,)
    np.testing.assert_allclose(np.asarray(qk["scale"]), np.max(np.abs(np.asarray(w)), 0) / 127, rtol=1e-6)
    err = np.abs(np.asarray(Q.dequantize(qk)) - np.asarray(w))
    assert np.all(err <= np.asarray(qk["scale"])[None] / 2 + 1e-7)
    assert Q.quantize_kernel(w, "bf16")["w"].dtype == jnp.bfloat16
    with pytest.raises(ValueError, match="fp32|bf16|int8"):
        Q.quantize_kernel(w, "int4")


@pytest.mark.parametrize("batch", [1, 8])
def test_qdense_dequantises_in_the_product(batch):
    rng = np.random.default_rng(batch)
    x = jnp.asarray(rng.normal(size=(batch, 33)), jnp.float32)
    w = jnp.asarray(rng.normal(size=(33, 12)), jnp.float32)
    b = jnp.asarray(rng.normal(size=12), jnp.float32)
    for fmt in Q.WEIGHT_FORMATS:
        qk = Q.quantize_kernel(w, fmt)
        want = np.asarray(x) @ np.asarray(Q.dequantize(qk), np.float64) + np.asarray(b)
        tol = 5e-2 if fmt == "bf16" else 1e-4  # the bf16 dot rounds x to bf16 as well
        np.testing.assert_allclose(np.asarray(jax.jit(Q.qdense)(x, qk, b)), want, rtol=tol, atol=tol)


def test_formats_of_the_generator():
    from benchmarks.cases import zeggs as Z
    from jaxgest.zeggs.config import preset

    cfg = preset("tiny").model
    params = Z.random_params(cfg, seed=3)
    inputs = Z.generator_inputs(cfg, 1, 40, seed=3)
    ref = jax.device_get(jax.jit(Z._generate_fn(cfg))(params, *inputs))
    gen = jax.jit(Q.make_generate(cfg))
    out = {f: jax.device_get(gen(Q.quantize_params(params, f), *inputs)) for f in Q.WEIGHT_FORMATS}
    for k in ref:
        np.testing.assert_allclose(out["fp32"][k], ref[k], rtol=1e-5, atol=1e-5, err_msg=k)
    for f in ("bf16", "int8"):
        d = np.abs(out[f]["pose"] - ref["pose"])
        assert 0 < d.max() < 0.1 and np.all(np.isfinite(out[f]["root_position"]))
    qp = Q.quantize_params(params, "int8")
    assert Q.weight_bytes(qp) < 0.3 * Q.weight_bytes(Q.quantize_params(params, "fp32"))


def test_inference_generate_takes_a_weight_format():
    from benchmarks.cases import zeggs as Z
    from jaxgest.errors import JaxgestError
    from jaxgest.zeggs.config import preset
    from jaxgest.zeggs.inference import TrainedZeggs
    from jaxgest.zeggs.model import apply_fns

    full = preset("tiny")
    cfg = full.model
    model = object.__new__(TrainedZeggs)  # the generation path only (no workdir)
    model.cfg, model.fns, model.quantized = full, apply_fns(cfg, full.inference.compiler_options), {}
    params = Z.random_params(cfg, seed=4)
    s, e, y0, r0, q0, f = Z.generator_inputs(cfg, 1, 30, seed=4)
    mean, std = jnp.zeros(cfg.pose_dim), jnp.ones(cfg.pose_dim)
    out = {fmt: model.run_generator(params, s, e, y0, r0, q0, f, mean, std, weight_format=fmt)
           for fmt in Q.WEIGHT_FORMATS}
    assert out["fp32"]["pose"].shape == (1, 31, cfg.pose_dim)
    for fmt in ("bf16", "int8"):
        d = np.abs(np.asarray(out[fmt]["pose"]) - np.asarray(out["fp32"]["pose"]))
        assert 0 < d.max() < 0.1
    with pytest.raises(JaxgestError, match="weight format"):
        model.generate("x.wav", [], weight_format="int4")


def test_zeggs_generate_cli_has_weight_format_next_to_blend_weights():
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "jaxgest.cli", "zeggs", "generate", "--help"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and "--weight-format {fp32,bf16,int8}" in r.stdout and "--weights" in r.stdout

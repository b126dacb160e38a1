"""PyTorch peers of the benchmark suite (run only when torch is installed: the ``[bench]`` extra).

The peers must equal the JAX models on the same weights (the harness refuses to time them otherwise), and
a plausible porting bug must be caught by that check.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from jaxgest.bench import harness, torch_peers as P  # noqa: E402

QUIET = dict(log=lambda s: None)


@pytest.fixture(scope="module")
def tgst_tiny():
    from jaxgest.tgst import model as M
    from jaxgest.tgst.config import preset

    cfg = preset("tiny").model
    cfg = dataclasses.replace(cfg, transformer=dataclasses.replace(cfg.transformer, variant="authors"))
    params = jax.jit(lambda k: M.init_params(cfg, k))(jax.random.key(1))
    rng = np.random.default_rng(0)
    c = rng.normal(scale=0.4, size=(2, 100, 39)).astype(np.float32)
    s = rng.normal(scale=0.4, size=(2, 64, 39)).astype(np.float32)

    def jit(p, content, style):
        up, lo, _ = M.transfer_arrays(p, content, style, cfg=cfg)
        return up, lo

    return cfg, params, c, s, jit


def test_tgst_peer_equals_the_jax_transfer_and_a_wrong_peer_is_caught(tgst_tiny):
    cfg, params, c, s, jit = tgst_tiny
    peer = P.load_tgst(cfg, params)
    case = lambda fn: harness.Case("peer", 2, 100, [harness.Impl("jit", jit, kind="jit"),  # noqa: E731
                                                    harness.Impl("torch", fn)],
                                   make_args=lambda: (params, c, s), rtol=1e-4, atol=1e-5)
    recs = harness.run_case(case(P.tgst_call(peer)), repeats=2, **QUIET)
    assert recs[1]["max_abs_diff"] < 1e-5
    # a porting bug: the decoder's ConvTranspose1d loaded without flipping the kernel
    wrong = P.load_tgst(cfg, params)
    with torch.no_grad():
        wrong.decoder.layers[1].weight.copy_(wrong.decoder.layers[1].weight.flip(-1))
    with pytest.raises(harness.EqualityError, match="^torch: output"):
        harness.run_case(case(P.tgst_call(wrong)), repeats=2, **QUIET)
    with pytest.raises(ValueError, match="variant='authors'"):
        P.TGSTPeer(dataclasses.replace(cfg, transformer=dataclasses.replace(cfg.transformer, variant="paper")))


def test_zeggs_peer_equals_the_jax_generator_and_a_wrong_peer_is_caught():
    from jaxgest.bench.cases import zeggs as Z
    from jaxgest.zeggs.config import preset

    cfg = preset("tiny").model
    params = Z.random_params(cfg, seed=2)
    inputs = Z.generator_inputs(cfg, 2, 20, seed=2)
    scale = np.ones(cfg.pose_dim, np.float32)
    case = lambda fn: harness.Case("zpeer", 2, 20, [harness.Impl("jit", Z._generate_fn(cfg), kind="jit"),  # noqa
                                                    harness.Impl("torch", fn)],
                                   make_args=lambda: (params,) + inputs, rtol=1e-4, atol=1e-4)
    recs = harness.run_case(case(P.zeggs_call(P.load_zeggs(cfg, params), scale)), repeats=2, **QUIET)
    assert recs[1]["max_abs_diff"] < 1e-4
    # a porting bug: GRU gates loaded in the order (z, r, n) instead of PyTorch's (r, z, n)
    wrong = P.load_zeggs(cfg, params)
    H = cfg.gru_hidden
    with torch.no_grad():
        w = wrong.recurrent_decoder.layer1.weight_ih_l0
        w.copy_(torch.cat([w[H:2 * H], w[:H], w[2 * H:]]))
    with pytest.raises(harness.EqualityError, match="^torch: output"):
        harness.run_case(case(P.zeggs_call(wrong, scale)), repeats=2, **QUIET)

"""Training-step and torch.compile peers of the benchmark suite (skipped without torch: the ``[bench]`` extra).

A training peer must give the JAX step's loss, loss terms, gradient norm and update norm on the same
weights and batch before it is timed, and a mis-ported peer (a wrong loss weight) must be refused.
"""

from __future__ import annotations

import dataclasses
import importlib.util

import pytest

from jaxgest.bench import harness

QUIET = dict(log=lambda s: None)


def test_training_peer_cases_build_without_torch_impls():
    from jaxgest.bench.cases import peers_train as PT

    case = PT.ae_case("tiny", with_torch=False)
    assert [i.name for i in case.impls] == ["jit"]


def _rec(impl, ms, compile_s=None, floor=None):
    return {"case": "c", "impl": impl, "median_us": ms * 1e3, "compile_s": compile_s, "floor_fraction": floor}


def test_compile_table_separates_eager_and_compiled_peers():
    from jaxgest.bench import report

    rows = [_rec("jit", 1.0, 2.0, 0.5), _rec("torch", 4.0), _rec("torch_1t", 3.0, None, 0.1),
            _rec("torch_compile", 2.0, 60.0, 0.25)]
    r = report.peer_compile_ratios(rows)["c"]
    assert (r["jit_vs_eager"], r["eager_impl"], r["jit_vs_compiled"], r["compile_s"]) == (3.0, "torch_1t", 2.0, 60.0)
    assert report.peer_ratios(rows) == {"c": {"jit": 3.0}}  # the eager peers only
    assert "| c | 1.00 | 3.00 | 2.00 | 3.00x | 2.00x | 2.0 | 60.0 | 50.0 % | 10.0 % | 25.0 % |" in \
        report.peer_compile_table(rows)


def test_an_implementation_is_checked_against_its_own_reference():
    outs = {"jit": {"y": 1.0}, "torch": {"y": 1.5}, "torch_compile": {"y": 1.5}}
    with pytest.raises(harness.EqualityError, match="^torch: "):
        harness.check_equal(outs, rtol=0, atol=1e-6)
    diffs = harness.check_equal({"jit": {"y": 1.0}, "torch": {"y": 1.0}, "torch_compile": {"y": 1.5}},
                                rtol=0, atol=1e-6, tolerances={"torch_compile": (0, 1.0)},
                                references={"torch_compile": "torch"})
    assert diffs["torch_compile"] == 0.5


def test_records_without_a_work_count_get_xla_flops_and_a_floor_fraction():
    import jax.numpy as jnp
    import numpy as np

    a = jnp.asarray(np.ones((64, 64), np.float32))
    case = harness.Case("mm", 1, 1, [harness.Impl("jit", lambda x: x @ x, kind="jit"),
                                      harness.Impl("numpy", lambda x: np.asarray(x) @ np.asarray(x))],
                        make_args=lambda: (a,))
    probe = {"gemm_gflops": 10.0, "mem_gbps": 10.0}
    recs = harness.run_case(case, repeats=2, probe=probe, **QUIET)
    for r in recs:
        assert r["flops"] == r["xla_flops"] == 2.0 * 64 ** 3  # XLA's count, the same for the numpy impl
        assert r["bytes"] == 2 * 64 * 64 * 4  # argument + output
        assert r["floor_bound"] == "compute" and 0 < r["floor_fraction"]
        harness.validate_record(r)


needs_torch = pytest.mark.skipif(importlib.util.find_spec("torch") is None,
                                 reason="the PyTorch peers need torch (pip install '.[bench]')")


@needs_torch
@pytest.mark.parametrize("stage", ["autoencoder", "transformer"])
def test_tgst_training_peer_equals_the_jax_step(stage):
    from jaxgest.bench.cases import peers_train as PT

    case = (PT.ae_case if stage == "autoencoder" else PT.transformer_case)("tiny", batch=2, window=128)
    recs = harness.run_case(case, repeats=2, impls=["jit", "torch"], **QUIET)
    jit, peer = recs
    assert peer["max_abs_diff"] is not None and peer["reference"] == "jit"
    assert jit["xla_flops"] > 0 and peer["flops"] == jit["flops"]


@needs_torch
def test_a_training_peer_with_a_wrong_loss_weight_is_refused():
    from jaxgest.bench.cases import peers_train as PT

    t = PT.config("tiny").train.transformer
    wrong = dataclasses.replace(t, lambda_cyclic=t.lambda_cyclic * 1.5)
    case = PT.transformer_case("tiny", batch=2, window=128, train=wrong)
    with pytest.raises(harness.EqualityError, match="^torch: output"):
        harness.run_case(case, repeats=2, impls=["jit", "torch"], **QUIET)


@needs_torch
@pytest.mark.slow
def test_compiled_autoencoder_training_peer_equals_the_eager_one():
    from jaxgest.bench.cases import peers_train as PT

    case = PT.ae_case("tiny", batch=2, window=64)
    recs = {r["impl"]: r for r in harness.run_case(case, repeats=2, impls=["jit", "torch", "torch_compile"],
                                                   **QUIET)}
    assert recs["torch_compile"]["reference"] == "torch"
    assert recs["torch_compile"]["compile_s"] > 0


ZEGGS_TINY = {"batch": 4, "window": 24, "style_frames": 16}  # the tiny preset, shorter windows: seconds


def _pose_stats(seed=0, dim=15 * 5 + 6):
    import numpy as np

    rng = np.random.default_rng(seed)
    return {"mean": rng.normal(scale=0.3, size=dim), "std": rng.uniform(0.5, 2.0, dim)}


@needs_torch
@pytest.mark.parametrize("variant", ["preset", "shuffled_rows_sum_kl_stats"])
def test_zeggs_training_peer_equals_the_jax_step(variant):
    """The tiny preset (no dropout, a rig); and with half the rows started from the previous row's pose,
    the exact KL (sum) and non-identity pose statistics (denormalised losses, group input scale)."""
    import jax

    from jaxgest.bench.cases import peers_train as PT

    if variant == "preset":
        case = PT.zeggs_case("tiny", **ZEGGS_TINY)
    else:
        fields = {"initial_pose_shuffle": 0.5, "initial_pose_source": "row", "kl_reduction": "sum"}
        cfg = PT.zeggs_config("tiny", **fields)
        assert PT.step_draws(cfg, jax.random.key(0), 0, ZEGGS_TINY["batch"])["swap"].any()
        case = PT.zeggs_case("tiny", fields=fields, stats=_pose_stats(), **ZEGGS_TINY)
    args = case.make_args()
    outs = {i.name: jax.device_get(harness.prepare(i, args)[1])
            for i in case.impls if i.name in ("jit", "torch")}
    assert set(outs["torch"]) == set(outs["jit"]) >= {"loss", "kl", "kl_weight", "facing", "grad_norm"}
    diff = harness.check_equal(outs, rtol=case.rtol, atol=case.atol)["torch"]  # raises beyond tolerance
    assert diff < 1e-2 * float(outs["jit"]["loss"])


@needs_torch
@pytest.mark.slow
def test_zeggs_training_peer_case_counts_every_generator_frame():
    from jaxgest.bench.cases import peers_train as PT

    case = PT.zeggs_case("tiny", **ZEGGS_TINY)
    jit, peer = harness.run_case(case, repeats=2, impls=["jit", "torch"], **QUIET)
    assert peer["max_abs_diff"] is not None and peer["reference"] == "jit"
    # XLA counts the generator's scan body once: the work adds the other frames' bodies
    assert jit["flops"] > jit["xla_flops"] > 0 and peer["flops"] == jit["flops"]


def test_zeggs_benchmark_draws_follow_the_steps_key_derivation():
    """The shuffle's swapped rows of step_draws are those of steps.initial_pose_swaps on the step's key."""
    import jax
    import numpy as np

    from jaxgest.bench.cases import peers_train as PT

    cfg = PT.zeggs_config("small", rig=False)
    assert cfg.train.initial_pose_shuffle > 0 and cfg.model.speech_dropout == 0.0
    d = PT.step_draws(cfg, jax.random.key(0), 0, 64)
    assert d["eps"].shape == (64, cfg.model.style_embedding) and 0 < d["swap"].sum() < 64
    assert not np.array_equal(d["swap"], PT.step_draws(cfg, jax.random.key(0), 1, 64)["swap"])


@needs_torch
@pytest.mark.parametrize("field", ["w_local_position", "kl_center"])
def test_a_zeggs_training_peer_with_a_wrong_loss_or_kl_weight_is_refused(field):
    from jaxgest.bench.cases import peers_train as PT

    cfg = PT.zeggs_config("tiny")
    wrong = cfg.override(**{field: getattr(cfg.train, field) * 1.5 if field != "kl_center" else 0.0})
    case = PT.zeggs_case("tiny", peer_cfg=wrong, **ZEGGS_TINY)
    with pytest.raises(harness.EqualityError, match="^torch: output"):
        harness.run_case(case, repeats=2, impls=["jit", "torch"], **QUIET)


@needs_torch
def test_the_zeggs_training_peer_refuses_what_it_does_not_port():
    from jaxgest.bench.cases import peers_train as PT
    from jaxgest.bench.torch_peers.zeggs_train import check_config
    from jaxgest.zeggs.config import preset

    with pytest.raises(ValueError, match="model.speech_dropout"):
        check_config(preset("tiny"))  # the preset trains with dropout
    with pytest.raises(ValueError, match="initial_pose_mask_seconds"):
        check_config(PT.zeggs_config("small").override(initial_pose_mask_seconds=0.5))
    check_config(PT.zeggs_config("small"))


@needs_torch
@pytest.mark.slow
def test_compiled_zeggs_training_peer_equals_the_eager_one():
    """torch.compile unrolls the generator's Python loop over frames: 8 frames compile in about a minute on 2
    cores, the other tests' 24 in about four."""
    from jaxgest.bench.cases import peers_train as PT

    case = PT.zeggs_case("tiny", **{**ZEGGS_TINY, "window": 8})
    recs = {r["impl"]: r for r in harness.run_case(case, repeats=2, impls=["jit", "torch", "torch_compile"],
                                                   **QUIET)}
    assert recs["torch_compile"]["reference"] == "torch"
    assert recs["torch_compile"]["compile_s"] > 0

"""The benchmark harness itself: equality check, a known-duration case, the JSON schema, reports, the CLI."""

from __future__ import annotations

import importlib.util
import json
import os
import pathlib
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgest.bench import suite as bench_main
from jaxgest.bench import harness, machine, report
from jaxgest.bench.cases import case_modules

REPO = pathlib.Path(__file__).resolve().parents[2]
CLI_CASE = "zeggs_generate_check_b1"  # a real case with jit / eager / numpy that runs in seconds
QUIET = dict(log=lambda s: None)


def _case(impls, **kw):
    x = np.linspace(0, 1, 64, dtype=np.float32)
    return harness.Case(name="tiny", batch=1, frames=64, impls=impls, make_args=lambda: (x,), **kw)


def _record(**kw):
    rec = dict(case="c", impl="jit", batch=1, frames=320, per_pose_us=1.5, compile_s=0.5, repeats=3,
               min_us=400.0, median_us=480.0, trace_s=0.01, lower_s=0.02, poses=320, group="g",
               peak_mem_mb=None)
    rec.update(kw)
    return rec


def test_equality_check_catches_a_wrong_implementation_before_timing():
    calls = {"numpy": 0}

    def counted(x):
        calls["numpy"] += 1
        return np.sin(x) * 2.0

    good = harness.Impl("jit", lambda x: jnp.sin(x) * 2.0, kind="jit")
    wrong = harness.Impl("wrong", lambda x: np.sin(x) * 2.0 + 1e-2)
    with pytest.raises(harness.EqualityError, match=r"^wrong: output differs from jit's"):
        harness.run_case(_case([good, harness.Impl("numpy", counted), wrong]), repeats=2, **QUIET)
    assert calls["numpy"] == 1  # run once for the check, never timed
    recs = harness.run_case(_case([good, harness.Impl("numpy", counted)]), repeats=2, **QUIET)
    assert [r["impl"] for r in recs] == ["jit", "numpy"]
    assert recs[1]["max_abs_diff"] < 1e-6 and calls["numpy"] > 3


def test_check_equal_names_shape_structure_and_non_finite_problems():
    with pytest.raises(harness.EqualityError, match=r"^b: output shape \(4,\)"):
        harness.check_equal({"a": np.zeros(3), "b": np.zeros(4)}, rtol=0, atol=0)
    with pytest.raises(harness.EqualityError, match="^b: output structure"):
        harness.check_equal({"a": (np.zeros(3),), "b": (np.zeros(3), np.zeros(3))}, rtol=0, atol=0)
    with pytest.raises(harness.EqualityError, match=r"^a: output\['y'\] is not finite"):
        harness.check_equal({"a": {"y": np.array([np.nan])}, "b": {"y": np.array([np.nan])}}, rtol=0, atol=0)
    with pytest.raises(harness.EqualityError, match=r"^b: output\[1\] differs .* 1 of 3 values"):
        harness.check_equal({"a": (np.zeros(3), np.ones(3)), "b": (np.zeros(3), np.array([1.0, 1.0, 1.1]))},
                            rtol=1e-3, atol=1e-3)
    diffs = harness.check_equal({"a": np.ones(3), "b": np.ones(3) + 1e-7}, rtol=1e-5, atol=1e-5)
    assert diffs["a"] == 0.0 and 0 < diffs["b"] < 1e-6


def test_known_sleep_is_measured_within_tolerance():
    sleeper = harness.Impl("sleep", lambda x: time.sleep(0.02) or x)
    (rec,) = harness.run_case(_case([sleeper]), repeats=3, **QUIET)
    assert 15_000 <= rec["median_us"] <= 60_000
    assert rec["min_us"] <= rec["median_us"] and rec["inner"] == 1
    assert 0 <= rec["cpu_median_us"] < 5_000  # sleeping uses no CPU: wall and CPU time are told apart
    assert rec["compile_s"] is None and rec["trace_s"] is None and rec["repeats"] == 3
    harness.validate_record(rec)


def test_time_budget_caps_repeats_but_keeps_two():
    times, inner = harness.time_steady(lambda: time.sleep(0.01), repeats=50, warmup=1, budget_s=0.05)
    assert 2 <= len(times) <= 3 and inner >= 2


def test_jit_records_time_trace_lower_compile_apart():
    impl = harness.Impl("jit", lambda x: jnp.cumsum(jnp.tanh(x)), kind="jit")
    (rec,) = harness.run_case(_case([impl]), repeats=2, **QUIET)
    for k in ("trace_s", "lower_s", "compile_s"):
        assert isinstance(rec[k], float) and rec[k] > 0
    assert rec["poses"] == 64 and rec["per_pose_us"] == pytest.approx(rec["median_us"] / 64)
    assert rec["per_frame_us"] == pytest.approx(rec["median_us"] / 64)  # batch 1: per frame = per pose
    assert rec["cpu_median_us"] > 0
    harness.validate_record(rec)


def test_each_jit_impl_is_compiled_once_and_its_executable_checked_and_timed():
    traces = []

    def f(x):
        traces.append(1)  # runs once per trace
        return jnp.sin(x) * 2.0

    recs = harness.run_case(_case([harness.Impl("jit", f, kind="jit"),
                                   harness.Impl("numpy", lambda x: np.sin(x) * 2.0)]), repeats=2, **QUIET)
    assert len(traces) == 1 and recs[0]["compile_s"] > 0 and recs[1]["max_abs_diff"] < 1e-6


def test_record_schema_is_validated():
    harness.validate_record(_record())
    harness.validate_record(_record(compile_s=None))
    for bad, msg in [
        ({"median_us": None}, "median_us"),
        ({"batch": "1"}, "batch"),
        ({"repeats": True}, "repeats"),
        ({"frames": 320.0}, "frames"),
        ({"min_us": 500.0}, "inconsistent"),
        ({"trace_s": "0.1"}, "trace_s"),
    ]:
        with pytest.raises(ValueError, match=msg):
            harness.validate_record(_record(**bad))
    missing = _record()
    del missing["per_pose_us"]
    with pytest.raises(ValueError, match="misses 'per_pose_us'"):
        harness.validate_record(missing)
    doc = {"machine": machine.machine_info(), "quick": True, "wall_s": 1.0, "records": [_record()],
           "ratios": {}, "failures": []}
    harness.validate_document(json.loads(json.dumps(doc)))
    with pytest.raises(ValueError, match="records"):
        harness.validate_document({k: v for k, v in doc.items() if k != "records"})


def test_reports_table_ratios_and_plot(tmp_path):
    recs = [_record(case=f"s{n}", impl=i, frames=n, poses=n, min_us=m, median_us=m, per_pose_us=m / n,
                    compile_s=0.5 if i == "jit" else None)
            for n in (320, 640) for i, m in (("jit", 100.0), ("eager", 400.0), ("numpy", 1000.0))]
    table = report.markdown_table(recs)
    assert "| s320 | eager | 1 | 320 | 1.25 | 400.0 | 400.0 |  | 3 | 4.00x |" in table
    rt = report.ratio_table(recs)
    assert rt.splitlines()[0].endswith("| eager/jit | numpy/jit |")
    assert "| s640 | 1 | 640 | 0.1562 | 0.625 | 1.562 | 4.00x | 10.00x |" in rt
    assert report.ratios(recs)["s320"] == {"eager": 4.0, "numpy": 10.0}
    ct = report.compile_table(recs).splitlines()
    assert len(ct) == 4 and ct[2] == "| s320 | jit | 0.01 | 0.02 | 0.50 | 0.3125 |"  # jit records only
    out = report.plot_scaling(recs, tmp_path / "scaling.png")
    assert out is not None and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert report.plot_scaling([_record(group="")], tmp_path / "none.png") is None


def test_case_selection_by_substring_and_glob():
    cases = [harness.Case(n, 1, 1, [], lambda: ()) for n in ("peer_tgst_b1", "peer_tgst_b8", "tgst_transfer_b1")]
    names = lambda pat: [c.name for c in bench_main.select(cases, pat)]  # noqa: E731
    assert names("b1") == ["peer_tgst_b1", "tgst_transfer_b1"]
    assert names("peer*,tgst_transfer") == [c.name for c in cases]
    assert names("peer_tgst_b?") == ["peer_tgst_b1", "peer_tgst_b8"] and names("nope") == []


def _conv_stack(params, x):
    """A tiny in-test case: two 1-D convolutions (lax.conv) with GELU between."""
    for i, (w, b) in enumerate(params):
        x = jax.lax.conv_general_dilated(x, w, window_strides=(2,), padding=[(1, 1)],
                                         dimension_numbers=("NWC", "WIO", "NWC")) + b[None, None]
        x = jax.nn.gelu(x, approximate=False) if i == 0 else x
    return x


def _conv_stack_numpy(params, x, *, flip=False):
    """The same stack as im2col + GEMM in NumPy; ``flip=True`` is a plausible bug (the kernel reversed)."""
    from math import erf

    h = np.asarray(x, np.float64)
    for i, (w, b) in enumerate(params):
        w = np.asarray(w, np.float64)[::-1] if flip else np.asarray(w, np.float64)
        hp = np.pad(h, ((0, 0), (1, 1), (0, 0)))
        cols = np.lib.stride_tricks.sliding_window_view(hp, 3, axis=1)[:, ::2]  # (B, F', C, k)
        h = np.einsum("bfck,kco->bfo", cols, w) + np.asarray(b)
        if i == 0:
            h = 0.5 * h * (1.0 + np.vectorize(erf)(h / np.sqrt(2.0)))
    return h


def test_a_wrong_implementation_of_a_conv_case_is_caught():
    rng = np.random.default_rng(0)
    params = [(jnp.asarray(rng.normal(size=(3, 5, 8)) / 4, jnp.float32), jnp.asarray(rng.normal(size=8), jnp.float32)),
              (jnp.asarray(rng.normal(size=(3, 8, 4)) / 5, jnp.float32), jnp.asarray(rng.normal(size=4), jnp.float32))]
    x = jnp.asarray(rng.normal(size=(2, 37, 5)), jnp.float32)

    def case(impls):
        return harness.Case("conv", 2, 37, impls, make_args=lambda: (params, x), rtol=1e-4, atol=1e-4)

    jit = harness.Impl("jit", _conv_stack, kind="jit")
    recs = harness.run_case(case([jit, harness.Impl("numpy", _conv_stack_numpy)]), repeats=2, **QUIET)
    assert recs[1]["max_abs_diff"] < 1e-4 and np.asarray(_conv_stack(params, x)).shape == (2, 10, 4)
    wrong = harness.Impl("numpy", lambda p, v: _conv_stack_numpy(p, v, flip=True))
    with pytest.raises(harness.EqualityError, match="^numpy: output differs from jit's"):
        harness.run_case(case([jit, wrong]), repeats=2, **QUIET)


def test_interleaved_rounds_time_each_impl_and_floor_fractions():
    slow = harness.Impl("slow", lambda x: time.sleep(0.01) or x)
    fast = harness.Impl("fast", lambda x: x)
    recs = harness.run_case(_case([slow, fast], interleave=True, work=lambda impl: (1e6, 1e6)), repeats=3, **QUIET)
    assert [r["impl"] for r in recs] == ["slow", "fast"] and all(r["interleaved"] for r in recs)
    assert recs[0]["repeats"] == recs[1]["repeats"] == 3
    assert 8_000 <= recs[0]["median_us"] <= 60_000 and recs[1]["median_us"] < 1_000
    probe = machine.probe_machine(0.2, gemm_n=256, stream_mb=32)
    assert probe["gemm_gflops"] > 0.1 and probe["mem_gbps"] > 0.1
    f = machine.floor(2e9, 1e6, 1.0, {"gemm_gflops": 4.0, "mem_gbps": 10.0})
    assert f == {"floor_bound": "compute", "floor_fraction": pytest.approx(0.5)}
    f = machine.floor(1e6, 1e10, 2.0, {"gemm_gflops": 4.0, "mem_gbps": 10.0})
    assert f["floor_bound"] == "memory" and f["floor_fraction"] == pytest.approx(0.5)
    for r in recs:
        harness.validate_record(r)
    rows = [dict(_record(case="p", impl=i, median_us=m, min_us=m), floor_bound="memory", floor_fraction=0.5,
                 flops=1e6, bytes=1e6) for i, m in (("jit", 100.0), ("int8", 50.0), ("torch", 300.0))]
    assert report.peer_ratios(rows) == {"p": {"jit": 3.0, "int8": 6.0}}
    rows.append(dict(rows[-1], impl="torch_1t", median_us=200.0, min_us=200.0))
    assert report.peer_ratios(rows) == {"p": {"jit": 2.0, "int8": 4.0}}
    assert "| p | 1 | 320 | int8 | 0.05 | 0.20 | 4.00x | memory | 50 % |" in report.peer_table(rows)
    assert report.floor_table(rows).count("| p |") == 4


def test_bench_options_match_python_m_benchmarks():
    import argparse

    from jaxgest.commands import bench

    sub = argparse.ArgumentParser().add_subparsers()
    bench.register(sub)
    (p,) = sub.choices.values()

    def opts(parser):
        return sorted((a.dest, tuple(a.option_strings), a.default) for a in parser._actions if a.dest != "help")

    assert opts(p) == opts(bench_main.build_parser())


def test_jaxgest_bench_help():
    r = subprocess.run([sys.executable, "-m", "jaxgest.cli", "bench", "--help"], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "--quick" in r.stdout and "--json" in r.stdout and "--cases" in r.stdout


def test_python_m_benchmarks_writes_valid_json_and_table(tmp_path):
    out = tmp_path / "bench.json"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-m", "benchmarks", "--quick", "--cases", CLI_CASE, "--repeats", "2",
                        "--json", str(out)], cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    harness.validate_document(doc)
    st = doc["stamp"]  # the provenance stamp: the commit of this checkout, the cases and settings, the command
    assert st["commit"] == subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True,
                                          text=True).stdout.strip() or st["commit"] is None
    assert st["config"] == {"cases": [CLI_CASE], "quick": True, "repeats": 2, "budget_s": st["config"]["budget_s"]}
    assert "--json" in st["command"] and st["version"]
    with pytest.raises(ValueError, match="stamp misses 'commit'"):
        harness.validate_document({**doc, "stamp": {k: v for k, v in st.items() if k != "commit"}})
    assert [(x["case"], x["impl"]) for x in doc["records"]] == [(CLI_CASE, i) for i in ("jit", "eager", "numpy")]
    assert doc["machine"]["cores"] >= 1 and doc["quick"] is True and doc["failures"] == []
    assert doc["machine"]["probe"]["gemm_gflops"] > 0 and doc["machine"]["probe"]["mem_gbps"] > 0
    assert set(doc["ratios"][CLI_CASE]) == {"eager", "numpy"}
    assert f"| {CLI_CASE} | jit | 1 |" in r.stdout and "| eager/jit | numpy/jit |" in r.stdout
    torch_line = "torch not installed: PyTorch peers skipped"
    assert (torch_line in r.stdout) == (importlib.util.find_spec("torch") is None)


def test_no_matching_case_is_a_one_line_error(tmp_path):
    # the suite is part of the package: the same one line from the clone's root and from anywhere else
    for cwd in (REPO, tmp_path):
        r = subprocess.run([sys.executable, "-m", "jaxgest.cli", "bench", "--cases", "no_such_case"], cwd=cwd,
                           capture_output=True, text=True, timeout=60,
                           env=dict(os.environ, PYTHONPATH=str(REPO)))
        assert r.returncode == 2 and r.stderr.strip() == "jaxgest: no benchmark case matches 'no_such_case'"


def test_numpy_reference_matches_the_jax_transfer():
    from jaxgest.bench import numpy_tgst
    from jaxgest.tgst.config import preset
    from jaxgest.tgst.model import init_params, transfer_arrays

    cfg = preset("paper").model
    params = jax.jit(lambda k: init_params(cfg, k))(jax.random.key(1))
    rng = np.random.default_rng(0)
    c = rng.normal(scale=0.4, size=(2, 100, 39)).astype(np.float32)
    s = rng.normal(scale=0.4, size=(2, 70, 39)).astype(np.float32)
    for method in ("soft", "hard"):
        up, lo, _ = jax.jit(transfer_arrays, static_argnames=("cfg", "method"))(params, c, s, cfg=cfg,
                                                                                 method=method)
        nu, nl = numpy_tgst.transfer(params, c, s, hard=method == "hard")
        np.testing.assert_allclose(np.asarray(up), nu, atol=2e-4)
        np.testing.assert_allclose(np.asarray(lo), nl, atol=2e-4)


@pytest.fixture(scope="module")
def zeggs_tiny():
    from jaxgest.bench.cases import zeggs as Z
    from jaxgest.zeggs.config import preset

    cfg = preset("tiny").model
    params = Z.random_params(cfg, seed=1)
    inputs = Z.generator_inputs(cfg, 2, 12, seed=1)
    out = jax.jit(Z._generate_fn(cfg))(params, *inputs)
    return cfg, params, inputs, jax.device_get(out)


def test_zeggs_random_params_have_the_init_shapes(zeggs_tiny):
    from jaxgest.zeggs.model import init_params

    cfg, params, _, _ = zeggs_tiny
    shapes = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.key(0))
    assert jax.tree_util.tree_structure(params) == jax.tree_util.tree_structure(shapes)
    assert all(a.shape == b.shape and a.dtype == b.dtype
               for a, b in zip(jax.tree_util.tree_leaves(params), jax.tree_util.tree_leaves(shapes)))
    assert np.all(np.asarray(params["style_encoder"]["conv0_norm"]["scale"]) == 1.0)
    k = np.asarray(params["generator"]["decoder"]["gru0"]["hidden"]["kernel"])
    assert 0.5 < k.std() * np.sqrt(k.shape[0]) < 1.5  # LeCun-normal scale


def test_numpy_zeggs_generator_and_variants_match_the_model(zeggs_tiny):
    from jaxgest.bench.cases import zeggs as Z
    from jaxgest.bench.cases import zeggs_variants as V

    cfg, params, inputs, ref = zeggs_tiny
    assert ref["pose"].shape == (2, 13, cfg.pose_dim) and np.all(np.isfinite(ref["pose"]))
    got = Z._numpy_generate(cfg)(params, *inputs)
    for k in ref:
        np.testing.assert_allclose(got[k], ref[k], rtol=1e-4, atol=1e-4, err_msg=k)
    for name, kw in V.VARIANTS.items():
        out = jax.jit(V.make_variant(cfg, **kw))(params, *inputs)
        for k in ref:
            np.testing.assert_allclose(np.asarray(out[k]), ref[k], rtol=1e-4, atol=1e-4,
                                       err_msg=f"{name} {k}")
    # bf16 kernels differ from float32, but not by much on a short sequence
    out = jax.jit(V.make_variant(cfg, hoist=True, fused=True, weight_dtype=jnp.bfloat16))(params, *inputs)
    err = np.max(np.abs(np.asarray(out["pose"]) - ref["pose"]))
    assert 0 < err < 0.1


def test_model_cases_are_registered_with_quick_and_full_presets():
    from jaxgest.bench.cases import all_cases

    def names(quick):
        return {c.name for c in all_cases(quick, log=lambda s: None) if c.quick or not quick}

    quick, full = names(True), names(False)
    for m in ("zeggs", "zeggs_variants", "training", "tgst"):
        assert f"jaxgest.bench.cases.{m}" in case_modules()
    assert {"zeggs_generate_check_b1", "zeggs_generate_b1", "zeggs_generate_b32", "zeggs_style_encoder_b1",
            "zeggs_speech_features", "train_tgst_autoencoder", "train_tgst_transformer",
            "train_zeggs_tiny"} <= quick
    assert "train_zeggs_paper" in full and "train_zeggs_paper" not in quick and "train_zeggs_tiny" not in full
    assert not any(n.startswith("zeggs_variant") for n in quick) and "zeggs_variants_b1" in full

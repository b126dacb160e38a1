"""The benchmark harness itself: equality check, a known-duration case, the JSON schema, the CLI."""

from __future__ import annotations

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

from benchmarks import harness, report
REPO = pathlib.Path(__file__).resolve().parents[1]


def _case(impls, **kw):
    x = np.linspace(0, 1, 64, dtype=np.float32)
    return harness.Case(name="toy", batch=1, frames=64, impls=impls, make_args=lambda: (x,), **kw)


def test_equality_check_catches_a_wrong_implementation():
    good = harness.Impl("jit", lambda x: jnp.sin(x) * 2.0, kind="jit")
    numpy_ok = harness.Impl("numpy", lambda x: np.sin(x) * 2.0)
    wrong = harness.Impl("wrong", lambda x: np.sin(x) * 2.0 + 1e-2)
    recs = harness.run_case(_case([good, numpy_ok]), repeats=2, log=lambda s: None)
    assert [r["impl"] for r in recs] == ["jit", "numpy"]
    with pytest.raises(harness.EqualityError, match="wrong: output differs"):
        harness.run_case(_case([good, wrong]), repeats=2, log=lambda s: None)
    with pytest.raises(harness.EqualityError, match="shape"):
        harness.check_equal({"a": np.zeros(3), "b": np.zeros(4)}, rtol=0, atol=0)


def test_known_sleep_is_measured_within_tolerance():
    sleeper = harness.Impl("sleep", lambda x: time.sleep(0.02) or x)
    (rec,) = harness.run_case(_case([sleeper]), repeats=3, log=lambda s: None)
    assert 19_000 <= rec["median_us"] <= 60_000
    assert rec["min_us"] <= rec["median_us"]
    assert rec["compile_s"] is None and rec["repeats"] == 3
    harness.validate_record(rec)


def test_jit_records_have_separate_trace_lower_compile_and_valid_schema():
    impl = harness.Impl("jit", lambda x: jnp.cumsum(jnp.tanh(x)), kind="jit")
    (rec,) = harness.run_case(_case([impl]), repeats=2, log=lambda s: None)
    for k in ("trace_s", "lower_s", "compile_s"):
        assert isinstance(rec[k], float) and rec[k] >= 0
    harness.validate_record(rec)
    bad = dict(rec)
    del bad["median_us"]
    with pytest.raises(ValueError, match="median_us"):
        harness.validate_record(bad)
    bad = dict(rec, batch="1")
    with pytest.raises(ValueError, match="batch"):
        harness.validate_record(bad)
    table = report.markdown_table([rec])
    assert "| toy | jit | 1 | 64 |" in table


def test_numpy_reference_matches_the_jax_transfer():
    from benchmarks import numpy_tgst
    from jaxgest.tgst.config import get_config
    from jaxgest.tgst.model import init_params, transfer_arrays

    cfg = get_config("paper")
    params = jax.jit(lambda k: init_params(cfg, k))(jax.random.PRNGKey(1))
    rng = np.random.default_rng(0)
    c = rng.normal(scale=0.4, size=(2, 100, 39)).astype(np.float32)
    s = rng.normal(scale=0.4, size=(2, 70, 39)).astype(np.float32)
    for method in ("soft", "hard"):
        up, lo, _ = jax.jit(transfer_arrays, static_argnames=("cfg", "method"))(params, c, s, cfg=cfg,
                                                                                 method=method)
        nu, nl = numpy_tgst.transfer(params, c, s, hard=method == "hard")
        np.testing.assert_allclose(np.asarray(up), nu, atol=2e-4)
        np.testing.assert_allclose(np.asarray(lo), nl, atol=2e-4)


@pytest.mark.slow
def test_suite_cli_writes_valid_json(tmp_path):
    out = tmp_path / "bench.json"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-m", "jaxgest.cli", "bench", "--quick", "--cases",
                        "tgst_stage_decode", "--repeats", "2", "--json", str(out)],
                       cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    data = json.loads(out.read_text())
    assert data["records"] and data["machine"]["cores"] >= 1
    for rec in data["records"]:
        harness.validate_record(rec)
    assert "| tgst_stage_decode_both | jit |" in r.stdout

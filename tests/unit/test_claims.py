"""The root README's claims table (experiments/claims.py): one verdict rule, and the table equals what the results
files give (a number or verdict that drifts from its results file, or from the rule, fails here)."""

import copy
import importlib.util
import pathlib

import pytest

from experiments import claims
from experiments.claims import FAILS, HOLDS, SAME_SIGN, Effect, interval, verdict


def test_t_quantiles_match_scipy():
    stats = pytest.importorskip("scipy.stats")
    for df, q in claims.T975.items():
        assert q == pytest.approx(float(stats.t.ppf(0.975, df)), abs=1e-4), df


def test_interval_is_t_based():
    m, lo, hi = interval([1.0, 2.0, 3.0])  # sd 1, SE 1/sqrt(3), t(2) 4.3027
    assert m == 2.0 and hi - m == pytest.approx(4.3027 / 3 ** 0.5, rel=1e-6) and m - lo == pytest.approx(hi - m)
    assert interval([0.5]) == (0.5, float("-inf"), float("inf"))


def test_t_rule_three_verdicts():
    assert verdict(Effect((-0.40, -0.30, -0.35), -1)) == HOLDS
    assert verdict(Effect((-0.40, -0.30, -0.35), +1)) == FAILS  # the same numbers against the other direction
    # L_identity, intra, as in the issue: 3 of 3 seeds up, but the interval spans zero
    assert verdict(Effect((0.004, 0.012, 0.011), +1)) == SAME_SIGN
    assert verdict(Effect((0.004, 0.012, 0.011), -1)) == FAILS
    assert verdict(Effect((0.02, -0.01, 0.02), +1)) == SAME_SIGN
    assert verdict(Effect((0.7,), +1)) == SAME_SIGN  # one measurement never holds
    assert verdict(Effect((-0.7,), +1)) == FAILS


def test_count_rule_is_the_registered_count():
    five = (0.01, 0.02, -0.01, 0.03, 0.01)
    assert verdict(Effect(five, +1, rule="count", passed=(1, 1, 0, 1, 1), need=4)) == HOLDS
    assert verdict(Effect(five, +1, rule="count", passed=(1, 0, 0, 1, 1), need=4)) == SAME_SIGN
    assert verdict(Effect(tuple(-x for x in five), +1, rule="count", passed=(1, 0, 0, 0, 0), need=4)) == FAILS
    with pytest.raises(ValueError):
        verdict(Effect(five, +1, rule="count", passed=(1, 1), need=4))


def _bn2_tables():
    spec = importlib.util.spec_from_file_location(
        "_test_bn2_tables", pathlib.Path(claims.ROOT) / "tgst_bandai2" / "tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("mean,se,per,want", [
    (-0.069, 0.031, (-0.07, -0.10, -0.03), HOLDS),
    (-0.114, 0.085, (-0.16, -0.13, -0.04), SAME_SIGN),  # below 2 SE
    (-0.069, 0.031, (-0.07, -0.10, 0.01), SAME_SIGN),   # one seed of the other sign
    (0.289, 0.077, (0.23, 0.24, 0.40), FAILS),
])
def test_pairs_rule_is_bandai2s_registered_rule(mean, se, per, want):
    """The "pairs" rule gives "holds" exactly where tgst_bandai2's own registered rule does."""
    e = Effect(per, -1, rule="pairs", need=3, pairs=(mean, se, 66))
    assert verdict(e) == want
    assert (_bn2_tables().holds((mean, se, 66, list(per), []), -1) == "**holds**") == (want == HOLDS)


def test_readme_claims_table_matches_the_results():
    assert claims.check() == []
    block = claims.BLOCK.search(claims.README.read_text()).group(0)
    rows = [line for line in block.splitlines() if line.startswith("| ") and not line.startswith("| paper")]
    assert len(rows) == sum(len(c.effects()) for c in claims.CLAIMS)
    for line in rows:
        assert line.split(" | ")[2].strip("*") in (HOLDS, SAME_SIGN, FAILS), line
        assert len(line) <= 200, line


def test_a_changed_result_is_caught(monkeypatch):
    """Control: L_identity's content error up by 0.1 m in every seed: the number and the verdict change."""
    real = claims._driver_results

    def perturbed(config):
        res = real(config)
        if "ablate_identity" in config:
            res = copy.deepcopy(res)
            for per in res["seeds"].values():
                for cond in ("intra", "inter"):
                    per["eval"][cond]["methods"]["soft"]["content"]["mean"] += 0.1
        return res

    perturbed.cache_clear = real.cache_clear
    monkeypatch.setattr(claims, "_driver_results", perturbed)
    assert claims.check() != []
    assert any("L_identity" in r and f"**{HOLDS}**" in r for r in claims.render().splitlines())

"""The README tables of the two run.sh experiments (zeggs_claims, tgst_bandai2) match their stamped results.

Each experiment's ``tables.py`` builds the tables from its results files; the README holds them between markers.
"""

import importlib.util
import pathlib
import re

import pytest

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[2] / "experiments"
CASES = {"zeggs_claims": (r"<!-- tables:start -->\n(.*)\n<!-- tables:end -->", "tables"),
         "tgst_bandai2": (r"<!-- tables -->\n(.*)\n<!-- /tables -->", "build")}


def _module(name):
    spec = importlib.util.spec_from_file_location(f"_tables_{name}", EXPERIMENTS / name / "tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", sorted(CASES))
def test_readme_tables_match_results(name):
    pattern, fn = CASES[name]
    m = re.search(pattern, (EXPERIMENTS / name / "README.md").read_text(), flags=re.S)
    assert m, f"{name}/README.md: no table markers"
    assert getattr(_module(name), fn)().strip() == m.group(1).strip(), \
        f"experiments/{name}/README.md differs from its results: run experiments/{name}/tables.py"


def test_zeggs_claims_detail_tables_match_results():
    path = EXPERIMENTS / "zeggs_claims" / "TABLES.md"
    assert path.read_text() == _module("zeggs_claims").detail_tables(), \
        "experiments/zeggs_claims/TABLES.md differs from its results: run experiments/zeggs_claims/tables.py"


def test_a_changed_claims_result_is_caught(monkeypatch):
    """Control: one number of one results file changed -> the generated tables differ."""
    mod = _module("zeggs_claims")
    real = mod.load
    docs = [r for r in mod.MAIN if real(r)]
    if not docs:
        pytest.skip("no zeggs_claims results file")
    before = mod.tables()

    def changed(run):
        d = real(run)
        if d and run == docs[0]:
            d["results"]["claims"]["style_portrayal"]["generated"]["mean"] += 0.1
        return d

    monkeypatch.setattr(mod, "load", changed)
    assert mod.tables() != before


def test_verdict_rule_decides_only_when_the_remaining_runs_cannot_change_it():
    verdict = _module("zeggs_claims").verdict
    assert verdict(4, 4).startswith("**holds**") and verdict(4, 5).startswith("**holds**")
    assert verdict(0, 2).startswith("**does not hold**") and verdict(3, 5).startswith("**does not hold**")
    assert verdict(1, 2).startswith("open") and verdict(0, 1).startswith("open") and verdict(3, 4).startswith("open")
    assert verdict(0, 1, 2, 2).startswith("**does not hold**") and verdict(1, 1, 2, 2).startswith("open")
    assert verdict(2, 2, 2, 2).startswith("**holds**")
    # a failed rule: the mean effect's sign picks the words (the project's one verdict rule, as the root table)
    assert verdict(0, 5, effect=0.01).startswith("**same sign, not significant**")
    assert verdict(0, 5, effect=-0.01).startswith("**does not hold**") and verdict(0, 5).startswith("**does not")
    assert verdict(4, 5, effect=-0.01).startswith("**holds**") and verdict(1, 2, effect=0.1).startswith("open")


def test_results_before_the_judge_correction_are_not_counted():
    mod = _module("zeggs_claims")
    stamp = {"config": {"thresholds": {"style_ratio": 0.9}}}
    assert not mod.judge_corrected({"stamp": stamp})
    stamp["config"]["thresholds"]["classifier_std_floor_fraction"] = 0.01
    assert mod.judge_corrected({"stamp": stamp})

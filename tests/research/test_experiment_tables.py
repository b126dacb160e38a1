"""Every README table the experiment driver generates matches its stamped results files, and every config loads.

A README table sits between ``<!-- table:NAME -->`` and ``<!-- /table -->``; ``python -m experiments table NAME``
writes it from the results files of its configs (see experiments/README.md).
"""

import copy
import pathlib

import pytest

from experiments import driver, tables

EXPERIMENTS = pathlib.Path(driver.__file__).parent
CONFIGS = sorted(EXPERIMENTS.glob("*/configs/*.toml"))


def _marked_tables():
    return [(readme, m["name"], bool(m["quick"])) for readme in tables._readmes() if readme.is_file()
            for m in tables.MARKER.finditer(readme.read_text())]


def test_every_readme_table_matches_its_results():
    assert tables.check() == []


def test_a_changed_result_is_caught(monkeypatch):
    """Control: perturb one number of the results a marked table is built from; the check must fail."""
    marked = [m for m in _marked_tables() if m[1] in tables.TABLES and tables.load_results(m[1], m[2])]
    if not marked:
        pytest.skip("no generated table with results in any README")
    readme, name, quick = marked[0]
    real = tables.load_results

    def perturbed(n, q):
        res = real(n, q)
        if n == name and q == quick:
            res = copy.deepcopy(res)
            seed = next(iter(res[-1]["seeds"].values()))
            for part in seed.get("eval", {}).values():  # tgst: scale every per-pair and averaged error
                for p in part["per_pair"]:
                    for e in list(p["errors"].values()) + list(p["controls"].values()):
                        e.update({k: v * 1.5 for k, v in e.items()})
                for e in list(part["methods"].values()) + list((part.get("controls") or {}).values()):
                    for g in ("content", "style"):
                        if g in e:
                            e[g] = {k: v * 1.5 for k, v in e[g].items()}
            if "metric_validity" in res[-1]:
                res[-1]["metric_validity"]["num_evaluated"] = -1
            for key in ("training_scripts", "heldout_scripts"):  # zeggs
                if key in seed:
                    seed[key]["frechet_distance"]["generated_vs_real"] *= 1.5
        return res

    monkeypatch.setattr(tables, "load_results", perturbed)
    assert any(f"table {name}" in line for line in tables.check())


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: f"{p.parent.parent.name}/{p.name}")
@pytest.mark.parametrize("quick", [False, True])
def test_config_loads_and_feeds_known_tables(path, quick):
    cfg = driver.load_config(path, quick)
    assert cfg["model"] in ("tgst", "zeggs") and cfg["seeds"]
    for name in cfg["table"]:
        assert name in tables.TABLES, f"{path}: unknown table {name}"
    if quick:
        full = driver.load_config(path, False)
        assert driver.results_path(cfg) != driver.results_path(full)
        assert driver.out_dir(cfg) != driver.out_dir(full)


def test_tables_name_existing_configs():
    for name, t in tables.TABLES.items():
        assert (EXPERIMENTS / t.readme).is_file(), name
        for c in t.configs:
            assert (EXPERIMENTS / c).is_file(), f"{name}: {c}"


def test_quick_replacements_are_dotted_paths():
    cfg = {"train": {"steps": 8000}, "seeds": [0, 1]}
    driver.set_dotted(cfg, "train.steps", 30)
    driver.set_dotted(cfg, "protocol.max_clips", 6)
    driver.set_dotted(cfg, "seeds", [0])
    assert cfg == {"train": {"steps": 30}, "seeds": [0], "protocol": {"max_clips": 6}}


def test_a_bad_config_is_one_line(tmp_path):
    (tmp_path / "configs").mkdir()
    bad = tmp_path / "configs" / "bad.toml"
    bad.write_text('model = "gan"\npreset = "x"\nseeds = [0]\ntable = []\n')
    with pytest.raises(driver.DriverError, match="model must be 'tgst' or 'zeggs'"):
        driver.load_config(bad)
    bad.write_text("model = [\n")
    with pytest.raises(driver.DriverError, match="not valid TOML"):
        driver.load_config(bad)


def test_readmes_stay_an_index():
    """The root README at most 200 lines, each experiment README at most 150, no README line over 200 characters."""
    root = EXPERIMENTS.parent / "README.md"
    assert len(root.read_text().splitlines()) <= 200
    for readme in sorted(EXPERIMENTS.glob("*/README.md")):
        assert len(readme.read_text().splitlines()) <= 150, readme
    for readme in [root, EXPERIMENTS / "README.md", *sorted(EXPERIMENTS.glob("*/README.md"))]:
        long = [i + 1 for i, line in enumerate(readme.read_text().splitlines()) if len(line) > 200]
        assert not long, f"{readme}: lines {long} over 200 characters"


def _write_seed(cfg, s, wall):
    from jaxgest.runtime.provenance import write_results

    dest = driver.results_path(cfg, s)
    dest.parent.mkdir(parents=True, exist_ok=True)
    write_results(dest, {"seeds": {str(s): {"probe": s}}, "wall_s": wall, "quick": False}, {**cfg, "seeds": [s]},
                  f"python -m experiments run {cfg['path']} --seeds {s}")


def test_seed_files_accumulate_and_merge(tmp_path, monkeypatch):
    """``run --seeds`` writes one stamped file per seed; the table merges them in the config's seed order and
    names the seeds still missing; ``merge`` refuses while a seed is missing, then folds them into the config's
    whole file (which keeps each seed file's stamp) and removes them."""
    monkeypatch.setattr(driver, "ROOT", tmp_path)
    (tmp_path / "zeggs_x" / "configs").mkdir(parents=True)
    path = tmp_path / "zeggs_x" / "configs" / "small.toml"
    path.write_text('table = []\nmodel = "zeggs"\npreset = "small"\nseeds = [0, 1, 2]\n')
    cfg = driver.load_config(path)
    assert driver.results_path(cfg, 2).name == "small.s2.json"
    assert driver.results_path({**cfg, "quick": True}, 0).name == "small.quick.s0.json"
    assert tables.load_config_results(cfg) is None
    _write_seed(cfg, 2, 30.0)
    _write_seed(cfg, 0, 10.0)
    res = tables.load_config_results(cfg)
    assert list(res["seeds"]) == ["0", "2"] and res["seeds"]["2"] == {"probe": 2}
    assert res["_missing"] == [1] and res["wall_s"] == 40.0 and res["_config"]["seeds"] == [0, 2]
    assert [p.name for p in res["_paths"]] == ["small.s0.json", "small.s2.json"]
    assert all(st["command"].endswith(f"--seeds {s}") for st, s in zip(res["_stamps"], (0, 2)))
    with pytest.raises(driver.DriverError, match="seeds 1 have no results file yet"):
        driver.merge([path], False)
    assert driver.results_path(cfg, 0).is_file()  # nothing removed by a refused merge
    _write_seed({**cfg, "train": {"steps": 10}}, 1, 20.0)  # a seed that ran another version of the config
    with pytest.raises(driver.DriverError, match="small.s1.json: ran another train than"):
        driver.merge([path], False)
    with pytest.raises(driver.DriverError, match="small.s1.json: ran another train than"):
        tables.load_config_results(cfg)
    _write_seed(cfg, 1, 20.0)
    assert driver.merge([path], False) == 0
    assert not any(driver.results_path(cfg, s).is_file() for s in range(3))
    whole = tables.load_config_results(cfg)
    assert whole["_missing"] == [] and whole["seeds"] == {str(s): {"probe": s} for s in range(3)}
    assert whole["wall_s"] == 60.0 and [p.name for p in whole["_paths"]] == ["small.json"]
    assert [st["command"].split()[-1] for st in whole["_stamps"]] == ["0", "1", "2"]  # the runs' own stamps
    assert [st["file"] for st in whole["_stamps"]] == [f"small.s{s}.json" for s in range(3)]


def test_wall_words_name_seeds_and_resumed_runs():
    """The wall line sums a config's seeds, says so, and names a seed resumed from a checkpoint (its wall time
    counts only the resumed part)."""
    one = {"wall_s": 90.0, "seeds": {"0": {}}, "_config": {"name": "small"}}
    assert tables.wall_words(one) == "90 s"
    two = {"wall_s": 600.0, "_config": {"name": "small"},
           "seeds": {"0": {"train": {"start_step": 0}}, "1": {"train": {"start_step": 1600}}}}
    assert tables.wall_words(two) == "10 min (2 seeds; seed 1 resumed at step 1600)"
    assert tables.wall_words(two, named=True).startswith("`small` 10 min")


def test_unknown_seed_is_one_line(capsys):
    path = next(c for c in CONFIGS if c.parent.parent.name == "zeggs_synthetic")
    assert driver.main(["run", str(path), "--seeds", "0", "77"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "seed 77 is not among the config's seeds" in err[0]
    cfg = driver.load_config(path)
    assert driver.select_seeds(cfg, [cfg["seeds"][-1], cfg["seeds"][0]]) == [cfg["seeds"][0], cfg["seeds"][-1]]


def _config_file(root, name, seeds):
    (root / "zeggs_x" / "configs").mkdir(parents=True, exist_ok=True)
    path = root / "zeggs_x" / "configs" / f"{name}.toml"
    path.write_text(f'table = []\nmodel = "zeggs"\npreset = "small"\nseeds = {list(seeds)}\n')
    return path


def test_partial_table_names_what_is_missing(tmp_path, monkeypatch):
    """A ``partial`` table renders from the configs that have results and says which seeds and configs are
    still to run; a table that is not ``partial`` waits for all of its configs; a whole results file with seed
    files beside it, or a merge over an existing whole file, is refused."""
    monkeypatch.setattr(driver, "ROOT", tmp_path)
    monkeypatch.setattr(tables, "ROOT", tmp_path)
    a, b = _config_file(tmp_path, "a", [0, 1]), _config_file(tmp_path, "b", [0, 1, 2])
    rows = lambda results: "\n".join(f"| `{r['_config']['name']}` | {s} |" for r in results for s in r["seeds"])
    name = "zeggs_x.headline"
    configs = ("zeggs_x/configs/a.toml", "zeggs_x/configs/b.toml")
    monkeypatch.setattr(tables, "TABLES", {name: tables.Table("zeggs_x/README.md", configs, rows, partial=True)})
    assert tables.block(name, False) is None
    cfg_b = driver.load_config(b)
    _write_seed(cfg_b, 1, 10.0)
    text = " ".join(tables.block(name, False).split())  # the stamp line is wrapped
    assert "`b` seeds 0, 2 not yet run" in text and "`a` not yet run" in text and "--seeds N" in text
    assert "| `b` | 1 |" in text and "| `a`" not in text and "small" not in text
    monkeypatch.setattr(tables, "TABLES", {name: tables.Table("zeggs_x/README.md", configs, rows)})
    assert tables.block(name, False) is None
    for s in (0, 2):
        _write_seed(cfg_b, s, 10.0)
    assert driver.merge([b], False) == 0
    _write_seed(cfg_b, 1, 10.0)  # a stale seed file beside the merged whole file
    with pytest.raises(driver.DriverError, match="b.s1.json lie beside it"):
        tables.load_config_results(cfg_b)
    with pytest.raises(driver.DriverError, match="b.json: exists; merging would replace it"):
        driver.merge([b], False)
    assert driver.load_config(a)["seeds"] == [0, 1]


def test_seeds_run_config_wide_parts_once(tmp_path, monkeypatch):
    """``--seeds`` runs the selected seeds in the config's order, each on its own; the parts computed once per
    config (TGST's Table 1) go with the config's first seed only, and merging keeps them."""
    path = _config_file(tmp_path, "c", [3, 1, 4])
    calls = []
    monkeypatch.setattr(driver, "run_one", lambda cfg, quick, seed, once=True: calls.append((cfg["seeds"], seed, once)))
    assert driver.run([path], False, [4, 3]) == 0
    assert calls == [([3], 3, True), ([4], 4, False)]
    calls.clear()
    assert driver.run([path], False, None) == 0
    assert calls == [([3, 1, 4], None, True)]
    assert driver.first_of([{"x": 1}, {"v": 2}, {"v": 3}], "v") == 2 and driver.first_of([{}], "v") is None


def test_run_rewrites_the_tables_its_configs_feed(tmp_path, monkeypatch):
    """One command regenerates a README table: ``run`` rewrites each table its configs feed once their
    results are at hand (here a partial table after one seed)."""
    monkeypatch.setattr(driver, "ROOT", tmp_path)
    monkeypatch.setattr(tables, "ROOT", tmp_path)
    path = _config_file(tmp_path, "d", [0, 1])
    path.write_text(path.read_text().replace("table = []", 'table = ["zeggs_x.t"]'))
    readme = tmp_path / "zeggs_x" / "README.md"
    readme.write_text("# x\n\n<!-- table:zeggs_x.t -->\nold\n<!-- /table -->\n\nafter\n")
    rows = lambda results: "\n".join(f"| `{r['_config']['name']}` | {s} |" for r in results for s in r["seeds"])
    monkeypatch.setattr(tables, "TABLES", {"zeggs_x.t": tables.Table("zeggs_x/README.md", ("zeggs_x/configs/d.toml",),
                                                                     rows, partial=True)})
    monkeypatch.setattr(driver, "run_one", lambda cfg, quick, seed, once=True: _write_seed(cfg, seed, 1.0))
    real_load = driver.load_config
    assert driver.run([path], False, [1]) == 0
    text = readme.read_text()
    assert "| `d` | 1 |" in text and "old" not in text and text.endswith("after\n")
    assert tables.check() == []  # the READMEs under this (temporary) experiments folder
    monkeypatch.setattr(driver, "load_config", lambda path, quick=False: {**real_load(path), "quick": quick})
    assert driver.run([path], True, [1]) == 0  # a smoke run: no marker for its table, so no table is added
    assert readme.read_text() == text


def _zeggs_seed(probe, leak, frechet, beat):
    rep = {"frechet_distance": {"generated_vs_real": frechet, "real_train_vs_real_test": 1.0},
           "beat_alignment": {"generated_vs_control": {"mean": beat, "standard_error": 0.01}},
           "leakage": {"contrasts": {"other_style - same_style_other_content": {"z": leak}}}}
    return {"pooled": {"probe_pooled": {"style": {"trained": probe, "raw_statistics": 0.9, "random_init": 0.7}}},
            "training_scripts": rep, "heldout_scripts": rep}


def test_zeggs_table_pairs_each_config_with_the_first_by_seed():
    """The paired row: the second config minus the first over their common seeds (mean ± SE of the differences;
    a seed only one config ran is left out)."""
    first = {"_config": {"name": "a"}, "seeds": {"0": _zeggs_seed(0.80, 3.0, 2.0, 0.05),
                                                 "1": _zeggs_seed(0.90, 4.0, 3.0, 0.07)}}
    second = {"_config": {"name": "b"}, "seeds": {"0": _zeggs_seed(0.85, 4.0, 1.0, 0.04),
                                                  "1": _zeggs_seed(0.93, 6.0, 2.0, 0.07),
                                                  "2": _zeggs_seed(0.10, 0.0, 9.0, 0.00)}}
    row = tables.render_zeggs([first, second]).splitlines()[-1]
    assert row.startswith("| `b` − `a` | paired, 2 seeds | +0.040 ± 0.010 | | | +1.50 ± 0.50 | -1.00 ± 0.00x |")
    assert row.endswith("| -0.005 ± 0.005 |")
    assert "paired" not in tables.render_zeggs([first])

"""jaxgest.bench.train_compare: loss curves from metrics.jsonl, final-loss tail, the report of two runs."""

from __future__ import annotations

import json

import pytest

from jaxgest.bench import train_compare as tc
from jaxgest.runtime.errors import DataError
from jaxgest.runtime.provenance import read_results


def _workdir(path, losses, seconds, commit, stage=None):
    path.mkdir(parents=True)
    with open(path / "metrics.jsonl", "w") as f:
        for i, v in enumerate(losses, 1):
            f.write(json.dumps({"step": 50 * i, "loss": v, **({"stage": stage} if stage else {})}) + "\n")
    (path / "wall.json").write_text(json.dumps({"seconds": seconds, "commit": commit}))


def test_curves_and_tail(tmp_path):
    _workdir(tmp_path / "w", [4.0, 3.0, 2.0, 1.0], 10.0, "a" * 40, stage="autoencoder")
    curves = tc.loss_curves(tc.read_metrics(tmp_path / "w"))
    assert curves == {"autoencoder": ([50, 100, 150, 200], [4.0, 3.0, 2.0, 1.0])}
    m, se = tc.tail_mean([4.0, 3.0, 2.0, 1.0], 2)
    assert m == 1.5 and se == pytest.approx(0.5)
    with pytest.raises(DataError, match="no metrics.jsonl"):
        tc.read_metrics(tmp_path / "missing")
    (tmp_path / "w" / "metrics.jsonl").write_text('{"step": 1}\nnot json\n')
    with pytest.raises(DataError, match=r"metrics.jsonl:2: not a JSON line"):
        tc.read_metrics(tmp_path / "w")


def test_report_of_two_finished_runs(tmp_path, capsys):
    """Sides with a wall.json are not rerun: the report, the PNG and the stamped results come from them."""
    _workdir(tmp_path / "before", [5.0, 4.0, 3.0, 2.0], 200.0, "b" * 40)
    _workdir(tmp_path / "after", [5.0, 4.0, 3.1, 2.2], 100.0, "c" * 40)
    png, js = tmp_path / "curves.png", tmp_path / "res.json"
    rc = tc.main(["--before", "x", "--after", "y", "--out", str(tmp_path), "--tail", "2", "--png", str(png),
                  "--json", str(js), "--", "zeggs", "train", "--seed", "0"])
    assert rc == 0 and png.stat().st_size > 1000
    res = read_results(js)["results"]
    assert res["speedup"] == pytest.approx(2.0)
    assert res["before"]["stages"]["train"]["final_loss"] == pytest.approx(2.5)
    assert res["after"]["steps_per_s"] == pytest.approx(2.0)
    assert "speed-up (wall, before / after): 2.000x" in capsys.readouterr().out
    assert tc.main(["--table", str(js)]) == 0
    table = capsys.readouterr().out
    assert "| before | bbbbbbb | 200 s | 1.00 | 2.5000 ± 0.5000 |" in table and "**2.00x**" in table


def test_missing_training_command_is_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit):
        tc.main(["--before", "x", "--out", str(tmp_path)])
    assert "give the training command after --" in capsys.readouterr().err


def test_paths_of_the_training_command_are_made_absolute(tmp_path, monkeypatch):
    (tmp_path / "data").mkdir()
    monkeypatch.chdir(tmp_path)
    out = tc.absolute_paths(["tgst", "train", "--data", "data", "--preset", "fit-motion", "--seed", "0"])
    assert out[3] == str((tmp_path / "data").resolve())
    assert out[:3] == ["tgst", "train", "--data"] and out[4:] == ["--preset", "fit-motion", "--seed", "0"]

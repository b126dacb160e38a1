"""`jaxgest plot W... --out curves.png` (jaxgest.commands.plot): the curves read from metrics.jsonl (a step
logged twice after a resume keeps its later line; held-out points where they were logged) and its errors."""

from __future__ import annotations

import json

import pytest
from PIL import Image

from jaxgest.commands.plot import curves, plot_training_curves
from jaxgest.runtime.errors import DataError


def _workdir(path, rows):
    path.mkdir()
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


ROWS = [
    {"step": 10, "stage": "autoencoder", "loss": 3.0, "devices": 1},
    {"step": 20, "stage": "autoencoder", "loss": 2.0, "eval_loss": 2.5},
    {"step": 30, "stage": "autoencoder", "loss": 9.0},  # logged, then killed before its checkpoint
    {"step": 30, "stage": "autoencoder", "loss": 1.5},  # ... and logged again after the resume
    {"step": 40, "stage": "autoencoder", "loss": 1.0, "eval_loss": 1.8},
    {"step": 10, "stage": "transformer", "loss": 5.0},
]


def test_curves():
    c = curves(ROWS, "loss")
    assert c["autoencoder"]["train"] == ([10, 20, 30, 40], [3.0, 2.0, 1.5, 1.0])
    assert c["autoencoder"]["eval"] == ([20, 40], [2.5, 1.8])
    assert c["transformer"] == {"train": ([10], [5.0]), "eval": ([], [])}
    assert curves(ROWS, "missing") == {}
    assert list(curves([{"step": 1, "loss": 1.0}], "loss")) == [""]  # rows without a stage


def test_plot_and_errors(tmp_path):
    a = _workdir(tmp_path / "a", ROWS)
    b = _workdir(tmp_path / "b", [{"step": 5, "stage": "zeggs", "loss": 4.0, "eval_loss": 4.5}])
    out = plot_training_curves([a, b], tmp_path / "c.png", labels=["A", "B"], log_y=True)
    w, h = Image.open(out).size
    assert w > 2.5 * h  # three stage panels side by side
    one = plot_training_curves([b], tmp_path / "one.svg")
    assert one.read_text().lstrip().startswith("<?xml")
    with pytest.raises(DataError, match="no metrics.jsonl"):
        plot_training_curves([tmp_path / "none"], tmp_path / "x.png")
    with pytest.raises(DataError, match=r"no 'angle' logged \(metrics: eval_loss, loss\)"):
        plot_training_curves([a], tmp_path / "x.png", metric="angle")
    with pytest.raises(DataError, match="--labels has 1 entries for 2 workdirs"):
        plot_training_curves([a, b], tmp_path / "x.png", labels=["A"])
    with pytest.raises(DataError, match="unknown image type '.jpg'"):
        plot_training_curves([a], tmp_path / "x.jpg")
    with pytest.raises(DataError, match="does not exist"):
        plot_training_curves([a], tmp_path / "no" / "x.png")
    assert not (tmp_path / "x.png").exists()

"""`jaxgest tgst evaluate --html DIR` and `jaxgest zeggs evaluate --html DIR`: viewer pages of the best,
median and worst cases (jaxgest.viewer.best_median_worst), on the session's tiny models."""

from __future__ import annotations

import json
import re

import pytest

from jaxgest import cli
from jaxgest.viewer import best_median_worst


def _titles(page):
    data = json.loads(re.search(r'id="jaxgest-data">(.*?)</script>', page.read_text(), re.S)[1])
    return [c["title"] for c in data["clips"]], data


def _expected(n):
    return sorted(["best.html", "worst.html", "median.html"][:min(n, 3)])


def test_best_median_worst():
    picked = best_median_worst(list("abcde"), [3, 1, 5, 2, 4])
    assert picked == [("best", "b"), ("median", "a"), ("worst", "c")]
    assert best_median_worst(["x", "y"], [2, 1]) == [("best", "y"), ("worst", "x")]  # lower median is best
    assert best_median_worst(["x"], [0.5]) == [("best", "x")]
    assert best_median_worst([], []) == []


@pytest.mark.slow
def test_tgst_evaluate_html(tiny, tmp_path, capsys):
    out = tmp_path / "pages"
    assert cli.main(["tgst", "evaluate", "--workdir", str(tiny["tw"]), "--data", str(tiny["data"]),
                     "--json", str(tmp_path / "r.json"), "--pairs", "all", "--methods", "soft,adain",
                     "--protocol", "world", "--html", str(out)]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    printed = capsys.readouterr().out
    evaluated = [r for r in report["per_pair"] if "content" in r["errors"]["soft"]]
    names = sorted(p.name for p in out.iterdir())
    assert names == _expected(len(evaluated)), names
    assert "3D viewer pages: " in printed
    titles, data = _titles(out / "best.html")
    assert titles[0] == "content" and titles[1].startswith("style (")
    assert titles[2].startswith("soft: ") and titles[3].startswith("adain: ")
    assert data["heading"].startswith("best pair (soft): ")
    assert data["audio"] is None  # no speech in style transfer


@pytest.mark.slow
def test_zeggs_evaluate_html(tiny, tmp_path, capsys):
    rows = ["path,content,style,audio"]
    for i, p in enumerate(sorted(tiny["data"].glob("*.bvh"))):  # two labelled styles of two clips each
        rows.append(f"{p.resolve()},c{i},{'ab'[i % 2]},{p.with_suffix('.wav').resolve()}")
    (tmp_path / "manifest.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "pages"
    assert cli.main(["zeggs", "evaluate", "--workdir", str(tiny["zw"]), "--data", str(tmp_path),
                     "--json", str(tmp_path / "r.json"), "--html", str(out)]) == 0
    result = json.loads((tmp_path / "r.json").read_text())
    per_clip = result["beat_alignment"]["per_clip"]
    assert len(per_clip) == result["beat_alignment"]["clips"] >= 1
    assert sorted(p.name for p in out.iterdir()) == _expected(len(per_clip))
    titles, data = _titles(out / "best.html")
    assert titles[0].startswith("generated: BeatAlign") and titles[1].startswith("real: ")
    assert data["options"]["trails"] and len(data["clips"]) == 3
    # the page plays the clip's speech (issue 60): as long as the page, from the clip's first frame
    speech = data["audio"]
    assert speech is not None and speech["src"].startswith("data:audio/") and speech["offset"] == 0
    assert speech["duration"] == pytest.approx(max(c["duration"] for c in data["clips"]), abs=1 / 16000)
    assert "media-src data:" in (out / "best.html").read_text()
    capsys.readouterr()


def test_html_dir_errors(tiny, tmp_path, capsys):
    base = ["--workdir", str(tiny["zw"]), "--data", str(tiny["data"]), "--json", str(tmp_path / "r.json")]
    assert cli.main(["zeggs", "evaluate", *base, "--html", str(tmp_path / "no" / "pages")]) == 2
    assert "parent" in capsys.readouterr().err
    assert cli.main(["zeggs", "evaluate", *base, "--no-generation", "--html", str(tmp_path / "p")]) == 2
    assert "--no-generation" in capsys.readouterr().err
    (tmp_path / "f").write_text("")
    assert cli.main(["tgst", "evaluate", "--workdir", str(tiny["tw"]), "--data", str(tiny["data"]),
                     "--json", str(tmp_path / "r.json"), "--html", str(tmp_path / "f")]) == 2
    assert "is a file" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()

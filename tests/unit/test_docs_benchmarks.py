"""docs/benchmarks.md against the stored result files it cites (issue 59, part 4): the AMD EPYC runs table
holds each file's TGST ratios, the done-when table lists every one of those runs, and every results file the
doc names exists."""

from __future__ import annotations

import json
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "benchmarks.md"
RESULTS = ROOT / "benchmarks" / "results"
_ROW = re.compile(r"^\| `(peers_amd[\w]*\.json)` \| ([\d.]+)x \| (?:\*\*)?([\d.]+)x")


def amd_rows(doc: str) -> dict[str, tuple[str, str]]:
    return {m[1]: (m[2], m[3]) for line in doc.splitlines() if (m := _ROW.match(line))}


def ratios(name: str) -> tuple[str, str]:
    r = json.loads((RESULTS / name).read_text())["peer_ratios"]
    return f"{r['peer_tgst_transfer_b1']['jit']:.2f}", f"{r['peer_tgst_transfer_b8']['jit']:.2f}"


def done_when_b8(doc: str) -> list[str]:
    """The AMD EPYC batch-8 ratios the done-when row "TGST transfer jit >= 3x ... at batch 8" lists."""
    line = next(line for line in doc.splitlines() if line.startswith("| TGST transfer jit ≥ 3x"))
    return re.findall(r"([\d.]+)x", line.split("AMD EPYC", 1)[1].split("(", 1)[0])


def test_amd_runs_table_holds_every_file_and_its_ratios():
    doc = DOC.read_text()
    rows = amd_rows(doc)
    assert set(rows) == {p.name for p in RESULTS.glob("peers_amd*.json")}
    assert {name: ratios(name) for name in rows} == rows
    assert sorted(done_when_b8(doc)) == sorted(b8 for _, b8 in rows.values())


def test_cited_results_files_exist():
    named = set(re.findall(r"benchmarks/results/([\w.-]+\.json)", DOC.read_text()))
    assert named and not {n for n in named if not (RESULTS / n).exists()}


def test_the_table_check_can_fail():
    doc = DOC.read_text()
    row = next(line for line in doc.splitlines() if line.startswith("| `peers_amd_s10.json`"))
    assert amd_rows(doc.replace(row, "")) != {p.name: ratios(p.name) for p in RESULTS.glob("peers_amd*.json")}
    altered = doc.replace(row, row.replace("2.74x", "2.47x"))
    rows = amd_rows(altered)
    assert rows["peers_amd_s10.json"] != ratios("peers_amd_s10.json")
    # the done-when row without the slowest run (as it was): not every run
    assert len(done_when_b8(doc.replace(" / 1.55x (six runs", " (six runs"))) == len(amd_rows(doc)) - 1

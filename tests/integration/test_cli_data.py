"""`jaxgest synth` and `jaxgest render` through the installed console script."""

from __future__ import annotations

import csv
import pathlib
import subprocess
import sys

import pytest
from PIL import Image

JAXGEST = pathlib.Path(sys.executable).with_name("jaxgest")


def run(*args, cwd=None):
    return subprocess.run([str(JAXGEST), *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "data"
    r = run("synth", "--out", out, "--clips", 2, "--seed", 3, "--seconds", 3)
    assert r.returncode == 0, r.stderr
    return out


def test_synth_then_render(synth_dir, tmp_path):
    rows = list(csv.DictReader(open(synth_dir / "manifest.csv", newline="")))
    assert len(rows) == 2 and all((synth_dir / r["path"]).is_file() and (synth_dir / r["audio"]).is_file() for r in rows)
    files = [synth_dir / r["path"] for r in rows]
    r = run("render", *files, "--out", tmp_path / "x.gif", "--titles", "a,b", "--max-seconds", 1)
    assert r.returncode == 0, r.stderr
    im = Image.open(tmp_path / "x.gif")
    assert im.n_frames == 20
    r = run("render", files[0], "--out", tmp_path / "x.png", "--png")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "x.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("case", ["missing", "malformed", "outdir", "titles"])
def test_bad_input_one_line_exit_2(case, synth_dir, tmp_path):
    good = next(synth_dir.glob("*.bvh"))
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    args = {
        "missing": ("render", tmp_path / "nope.bvh", "--out", tmp_path / "o.gif"),
        "malformed": ("render", bad, "--out", tmp_path / "o.gif"),
        "outdir": ("render", good, "--out", tmp_path / "no" / "o.gif"),
        "titles": ("render", good, "--out", tmp_path / "o.gif", "--titles", "a,b"),
    }[case]
    r = run(*args)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxgest: ") and "Traceback" not in r.stderr

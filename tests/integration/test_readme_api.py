"""The README's Python API block runs: ``docs/api_example.py`` (the block's source) and the first ```python
block of README.md (once the README has it: then it must be the snippet, verbatim), in a folder holding what
they name -- the session's tiny
TGST and ZeroEGGS workdirs as ``runs/tgst`` and ``runs/zeggs``, synthetic clips as ``content.bvh``,
``style.bvh``, ``calm.bvh``, ``happy.bvh`` and ``speech.wav``."""

from __future__ import annotations

import os
import pathlib
import re

import pytest

from jaxgest.motion import bvh

REPO = pathlib.Path(__file__).resolve().parents[2]
SNIPPET = REPO / "docs" / "api_example.py"
MAX_LINES = 10  # the README's API block is at most this long


def readme_block() -> str | None:
    """The first ```python block of README.md, or None (no README, or no such block yet)."""
    readme = REPO / "README.md"
    if not readme.is_file():
        return None
    m = re.search(r"^```python\n(.*?)^```", readme.read_text(), re.S | re.M)
    return m.group(1) if m else None


@pytest.fixture
def example_folder(tmp_path, tiny_data, tgst_workdir, zeggs_workdir, monkeypatch):
    (tmp_path / "runs").mkdir()
    os.symlink(tgst_workdir, tmp_path / "runs" / "tgst")
    os.symlink(zeggs_workdir, tmp_path / "runs" / "zeggs")
    clips = sorted(tiny_data.glob("*.bvh"))
    for name, clip in zip(("content", "style", "calm", "happy"), clips):
        os.symlink(clip, tmp_path / f"{name}.bvh")
    os.symlink(sorted(tiny_data.glob("*.wav"))[0], tmp_path / "speech.wav")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run(source: str, folder: pathlib.Path) -> None:
    code = compile(source, str(SNIPPET), "exec")
    exec(code, {"__name__": "__readme__"})
    written = {p.name for p in folder.glob("*.bvh") if not p.is_symlink()}
    assert written, "the API block wrote no BVH file"
    for name in written:
        m = bvh.load(folder / name)
        assert m.num_frames > 0


def test_snippet_is_short_and_runs(example_folder):
    source = SNIPPET.read_text()
    lines = [line for line in source.splitlines() if line.strip()]
    assert len(lines) <= MAX_LINES, f"{SNIPPET} has {len(lines)} lines (README block: <= {MAX_LINES})"
    run(source, example_folder)
    assert {"styled.bvh", "gestures.bvh"} <= {p.name for p in example_folder.iterdir()}


def test_readme_block_is_the_snippet_and_runs(example_folder):
    block = readme_block()
    if block is None or "import jaxgest as jg" not in block:
        pytest.skip("README.md has no API block (```python ... import jaxgest as jg) yet")
    assert block.strip() == SNIPPET.read_text().strip(), f"README.md's API block differs from {SNIPPET}"
    run(block, example_folder)

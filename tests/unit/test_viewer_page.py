"""The HTML viewer page (jaxgest.viewer): embedded positions against forward kinematics, self-containment,
size, and `jaxgest render` choosing the output by its extension. The page itself runs in a browser in
tests/integration/test_viewer_browser.py."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from jaxgest import viewer
from jaxgest.runtime.errors import DataError
from jaxgest.motion import bvh
from jaxgest.motion.kinematics import forward_kinematics
from jaxgest.motion.skeleton import Motion, Skeleton
from jaxgest.motion.synthetic import CONTENTS, render_clip


@pytest.fixture(scope="module")
def clips():
    spec = CONTENTS["greeting"].with_seed(0, 2.0)
    return [render_clip(spec, s, seed=0)[0] for s in ("neutral", "energetic")]


def _embedded(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="jaxgest-data">(.*?)</script>', page, re.S)
    assert m, "no data block"
    return json.loads(m.group(1))


def _random_motion(frames, joints, fps, travel_m=0.0, seed=0, up_axis=1):
    """A chain-and-branches skeleton with random rotations; the root travels ``travel_m`` metres along X."""
    rng = np.random.default_rng(seed)
    parents = np.array([-1] + [int(rng.integers(0, j)) for j in range(1, joints)])
    offsets = rng.normal(0, 8.0, (joints, 3))
    names = [f"j{j}" for j in range(joints)]
    sk = Skeleton(names=names, parents=parents, offsets=offsets, up_axis=up_axis)
    q = rng.normal(0, 1, (frames, joints, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    tr = np.broadcast_to(offsets, (frames, joints, 3)).copy()
    tr[:, 0, 0] = np.linspace(0, travel_m * 100, frames)
    tr[:, 0, 1] = 90.0
    return Motion(sk, q, tr, fps, name="random")


@pytest.mark.parametrize("case", ["synthetic", "travelling", "z_up"])
def test_embedded_positions_match_forward_kinematics(clips, case):
    m = {"synthetic": clips[1], "travelling": _random_motion(90, 30, 30.0, travel_m=8.0),
         "z_up": _random_motion(40, 12, 25.0, seed=1, up_axis=2)}[case]
    page = viewer.html_page([m], ["x"])
    rec = _embedded(page)["clips"][0]
    got = viewer.decode_clip(rec)
    want = np.asarray(forward_kinematics(m), np.float64) * viewer.CM_TO_M
    if m.skeleton.up_axis == 2:  # Z-up -> Y-up, right-handed: (x, y, z) -> (y, z, x)
        want = np.roll(want, -1, axis=-1)
        assert np.allclose(got[..., 1], want[..., 1], atol=1e-4)
    assert got.shape == want.shape
    assert np.abs(got - want).max() < 1e-4  # 0.1 mm
    assert rec["frames"] == m.num_frames and rec["fps"] == m.fps
    assert rec["duration"] == pytest.approx(m.duration)


def test_page_is_self_contained_and_labelled(clips, tmp_path):
    out = viewer.render_html(clips, tmp_path / "v.html", titles=["content </script> <b>", "result"])
    page = out.read_text()
    assert page.startswith("<!DOCTYPE html>")
    assert "Content-Security-Policy" in page and "default-src 'none'" in page  # the browser refuses any fetch
    assert not re.search(r"<(script|link|img|iframe)[^>]*\s(src|href)=", page, re.I)
    assert not re.search(r"https?://", page)
    assert "{{" not in page  # every template slot filled
    data = _embedded(page)
    assert [c["title"] for c in data["clips"]] == ["content </script> <b>", "result"]
    c = data["clips"][0]
    assert c["side"].count("L") >= 4 and c["side"].count("R") >= 4 and c["head"] >= 0
    names = c["joints"]
    assert sorted(names[j] for j in c["hands"]) == ["Hand_L", "Hand_R"]
    assert {names[j] for j in c["feet"]} == {"Foot_L", "Toes_L", "Foot_R", "Toes_R"}
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def test_size_of_three_ten_second_clips(tmp_path):
    """Three 10 s clips at 30 fps of a 75-joint rig (the ZEGGS rig's size) stay under 1.5 MB."""
    motions = [_random_motion(300, 75, 30.0, seed=s) for s in range(3)]
    out = viewer.render_html(motions, tmp_path / "three.html")
    assert out.stat().st_size < 1.5e6, out.stat().st_size


def test_bad_arguments(clips, tmp_path):
    with pytest.raises(DataError, match="titles"):
        viewer.render_html(clips, tmp_path / "x.html", titles=["one"])
    with pytest.raises(DataError, match="does not exist"):
        viewer.render_html(clips, tmp_path / "missing" / "x.html")
    with pytest.raises(DataError, match="window"):
        viewer.render_html(clips, tmp_path / "x.html", trail_seconds=0)


def test_render_cli_chooses_by_extension(clips, tmp_path, capsys):
    from types import SimpleNamespace

    from jaxgest.cli import main

    def _cli(*args):  # in-process (the CLI's own subprocess tests cover the entry point)
        rc = main([str(a) for a in args])
        cap = capsys.readouterr()
        return SimpleNamespace(returncode=rc, stdout=cap.out, stderr=cap.err)

    paths = []
    for k, m in enumerate(clips):
        paths.append(tmp_path / f"c{k}.bvh")
        bvh.save(m, paths[-1])
    r = _cli("render", *paths, "--out", tmp_path / "v.html", "--titles", "a,b", "--trails", "2")
    assert r.returncode == 0, r.stderr
    page = (tmp_path / "v.html").read_text()
    data = _embedded(page)
    assert [c["title"] for c in data["clips"]] == ["a", "b"] and data["options"]["trailSeconds"] == 2.0
    r = _cli("render", paths[0], "--out", tmp_path / "v.gif", "--max-seconds", "0.3")
    assert r.returncode == 0 and (tmp_path / "v.gif").read_bytes()[:4] == b"GIF8"
    r = _cli("render", paths[0], "--out", tmp_path / "v.png")
    assert r.returncode == 0 and (tmp_path / "v.png").read_bytes()[:4] == b"\x89PNG"
    for out, why in (("v.mp4", "unknown output type '.mp4'"),
                     ("noext", "unknown output type '(no extension)'")):
        r = _cli("render", paths[0], "--out", tmp_path / out)
        assert r.returncode == 2 and why in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not (tmp_path / out).exists()
    r = _cli("render", paths[0], "--png", "--out", tmp_path / "still.gif")
    assert r.returncode == 2 and "name the output .png" in r.stderr

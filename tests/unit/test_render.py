"""Stick-figure GIF / PNG rendering."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from jaxgest.runtime.errors import DataError
from jaxgest.motion.synthetic import CONTENTS, render_clip
from jaxgest.render import project, render_gif, render_png


@pytest.fixture(scope="module")
def clips():
    spec = CONTENTS["greeting"].with_seed(0, 2.0)
    return [render_clip(spec, s, seed=0)[0] for s in ("neutral", "energetic")]


def test_gif_frames_and_panels(tmp_path, clips):
    one = render_gif(clips[0], tmp_path / "one.gif")
    two = render_gif(clips, tmp_path / "two.gif", titles=["content", "result"], fps=10)
    a, b = Image.open(one), Image.open(two)
    assert a.n_frames == 40 and b.n_frames == 20  # 2 s at min(60, 20) fps, and at 10 fps
    assert b.size[0] == pytest.approx(2 * a.size[0], abs=2) and b.size[1] == a.size[1]
    short = render_gif(clips, tmp_path / "short.gif", fps=10, max_seconds=0.5)
    assert Image.open(short).n_frames == 5
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files left


def test_png_and_errors(tmp_path, clips):
    out = render_png(clips, tmp_path / "still.png", frame=10, titles=["a", "b"])
    im = np.asarray(Image.open(out).convert("L"))
    assert im.min() < 100  # something dark (the figure) was drawn
    with pytest.raises(DataError, match="does not exist"):
        render_gif(clips[0], tmp_path / "missing" / "x.gif")
    with pytest.raises(DataError, match="titles"):
        render_gif(clips, tmp_path / "x.gif", titles=["only one"])
    with pytest.raises(DataError, match="frame"):
        render_png(clips[0], tmp_path / "x.png", frame=10_000)


def test_projection_front_view():
    p = np.array([[10.0, 0.0, 0.0], [0.0, 10.0, 0.0]])
    q = project(p, yaw_deg=0.0, elev_deg=0.0)
    np.testing.assert_allclose(q, [[10.0, 0.0], [0.0, 10.0]], atol=1e-12)  # the character's left is image right

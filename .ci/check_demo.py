"""CI check of `jaxgest demo` outputs: every GIF has more than one frame, every BVH loads in an independent
parser (tests/helpers/bvh_testing.py:reference_fk, scipy rotations) with the same joint positions as jaxgest's FK, and
metrics.json holds finite numbers."""

import json
import math
import pathlib
import sys

import numpy as np
from PIL import Image

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "helpers"))
from bvh_testing import reference_fk  # noqa: E402

from jaxgest.motion import bvh, kinematics  # noqa: E402

out = pathlib.Path(sys.argv[1])
gifs, files = sorted(out.glob("results/*.gif")), sorted(out.glob("results/*.bvh"))
assert len(gifs) >= 4 and len(files) >= 12, (gifs, files)
for g in gifs:
    with Image.open(g) as im:
        assert im.n_frames > 1, f"{g}: {im.n_frames} frame"
for f in files:
    ref, names, _ = reference_fk(f)
    mine = kinematics.forward_kinematics(bvh.load(f))
    assert np.abs(ref - mine).max() < 1e-3, f
report = json.loads((out / "metrics.json").read_text())


def finite(x):
    if isinstance(x, dict):
        return all(finite(v) for v in x.values())
    if isinstance(x, list):
        return all(finite(v) for v in x)
    return not isinstance(x, float) or math.isfinite(x)


assert finite(report["style_transfer"]) and finite(report["timings_s"])
# the transfer table: the four methods and the two controls, each naming its metric protocol; the controls
# are exact by construction (the content as is has no content error, the style as is no style error)
for style, rows in report["style_transfer"].items():
    assert {"soft", "hard", "adain", "avatarnet", "content_as_is", "style_as_is"} <= set(rows), (style, rows)
    assert all(r["protocol"] == "authors" for r in rows.values()), style
    assert rows["content_as_is"]["content"]["worst"] == 0.0 and rows["style_as_is"]["style"]["worst"] == 0.0
    assert all(r["style"]["mean"] > 0 for m, r in rows.items() if m != "style_as_is"), style
gen = report["generation"]
assert finite(gen), "generation metrics hold a NaN or inf"
probe = gen["style_probe"]  # the ZeroEGGS probe comes with its controls, on the same folds
for task in ("style", "content"):
    for k in ("trained", "random_init", "raw_statistics"):
        assert 0.0 <= probe[task][k]["accuracy"] <= 1.0 and probe[task][k]["ci95_half_width"] >= 0.0, (task, k)
lk = gen["leakage"]["contrasts"]  # and the leakage contrast (same style vs another style)
assert {"other_style - same_style_other_content", "zero - same_style_other_content"} <= set(lk), lk
print(f"demo outputs ok: {len(gifs)} GIFs, {len(files)} BVH files (independent parser), metrics.json "
      f"({report['timings_s']['total_s']:.0f} s)")

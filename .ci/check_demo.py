"""CI check of `jaxgest demo` outputs: every GIF has more than one frame, every BVH loads in an independent
parser (tests/helpers/bvh_testing.py:reference_fk, scipy rotations) with the same joint positions as jaxgest's FK,
the HTML viewer pages are there, self-contained, with their panels' clips as the BVH files (and, when
headless Chromium is installed, draw without a JavaScript error or a request), and metrics.json holds finite
numbers."""

import json
import math
import pathlib
import re
import sys

import numpy as np
from PIL import Image

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "helpers"))
from browser_testing import Browser, find_chromium  # noqa: E402
from bvh_testing import reference_fk  # noqa: E402

from jaxgest import viewer  # noqa: E402
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

# the HTML viewer pages: listed in the summary, self-contained, each clip as its BVH file
PAGES = {"transfer_energetic.html": ["content (neutral)", "style (energetic)", "soft", "hard", "adain",
                                     "avatarnet", "ground truth"],
         "transfer_sad.html": None, "speech_styles.html": ["energetic", "sad", "blend 50/50"],
         "pipeline.html": ["ZeroEGGS (neutral)", "+ TGST (energetic)", "style exemplar"]}
assert sorted(report["pages"]) == sorted(PAGES), report["pages"]
for name, titles in PAGES.items():
    page = (out / "results" / name).read_text()
    assert "default-src 'none'" in page and not re.search(r"<(script|link|img)[^>]*\s(src|href)=", page), name
    data = json.loads(re.search(r'id="jaxgest-data">(.*?)</script>', page, re.S)[1])
    shown = [c["title"] for c in data["clips"]]
    assert titles is None or shown == titles, (name, shown)
    assert all(c["frames"] > 1 and c["fps"] > 0 for c in data["clips"]), name
energetic = json.loads(re.search(r'id="jaxgest-data">(.*?)</script>',
                                 (out / "results/transfer_energetic.html").read_text(), re.S)[1])["clips"]
soft = viewer.decode_clip(energetic[2])  # the soft transfer's panel is results/transfer_energetic_soft.bvh
want = kinematics.forward_kinematics(bvh.load(out / "results/transfer_energetic_soft.bvh")) * viewer.CM_TO_M
assert np.abs(soft - want).max() < 1e-4, "transfer_energetic.html: soft panel differs from its BVH"
if find_chromium():  # drawn in a real browser: no JavaScript error, no request but the page
    for name in PAGES:
        url = (out / "results" / name).resolve().as_uri()
        with Browser() as b:
            b.open(url + "#t=1&paused=1")
            b.next_frame()
            assert b.js_errors() == [] and {u.split("#")[0] for u in b.requests()} <= {url}, name
    browser = "drawn in headless Chromium"
else:
    browser = "not drawn: no headless Chromium"


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
print(f"demo outputs ok: {len(gifs)} GIFs, {len(files)} BVH files (independent parser), {len(PAGES)} HTML "
      f"pages "
      f"({browser}), metrics.json ({report['timings_s']['total_s']:.0f} s)")

"""Lower bound of the content error of ANY collage of a style clip's frames (no model): per content frame,
the distance to the nearest style frame in the metric's own feature (both hands' root-local positions), next
to the content error of the style clip as is (DTW) and of the ground truth (the content performed in the
target style; intra: the style clip itself).

    python experiments/tgst_bandai/collage_bound.py EVAL_DIR OUT_JSON [--trim 0.3]

Each DTW-aligned pair of a content frame with one of the style's poses costs at least that content frame's
``nearest_frame`` distance, so an output made of the style's poses gets below the mean only through the uneven
weighting of the DTW path (content frames aligned more than once), not by picking better poses. Approximate for
decoded outputs (a decoded collage is not exactly the style's poses) and for blends (which leave them).
References: Kuriyama et al. 2022, eqs. 13-14 (content error).
"""
import argparse
import json
import sys

import numpy as np

from jaxgest import metrics
from jaxgest.motion.datasets import load_folder
from jaxgest.tgst.evaluate import make_pairs
from jaxgest.tgst.protocol import clip_features, get_protocol


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("eval_dir"), ap.add_argument("out")
    ap.add_argument("--trim", type=float, default=0.3)
    a = ap.parse_args(argv[1:])
    proto = get_protocol("authors", a.trim)
    clips = load_folder(a.eval_dir)
    report = {"protocol": proto.describe()}
    for mode in ("intra", "inter"):
        rows = []
        for p in make_pairs(clips, mode):
            fps = p.content.motion.fps
            c = clip_features(p.content.motion, fps, proto)[0]
            s = clip_features(p.style.motion, fps, proto)[0]
            d = np.linalg.norm(c[:, None, :] - s[None, :, :], axis=-1)
            row = {"content": str(p.content.path), "style": str(p.style.path),
                   "nearest_frame": float(d.min(1).mean()),
                   "style_as_is": metrics.content_error(c, s)["mean"]}
            if p.ground_truth is not None:
                g = clip_features(p.ground_truth.motion, fps, proto)[0]
                row["ground_truth"] = metrics.content_error(c, g)["mean"]
            rows.append(row)
        keys = ("nearest_frame", "style_as_is", "ground_truth")
        report[mode] = {"mean": {k: float(np.mean([r[k] for r in rows if k in r])) for k in keys},
                        "n": {k: sum(k in r for r in rows) for k in keys}, "per_pair": rows}
        print(mode, report[mode]["mean"], report[mode]["n"])
    with open(a.out, "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    main(sys.argv)

"""Why Table 1's style metric is not valid on Bandai-Namco: is a clip's arm-velocity style closer to the same
content in another style, or to another content in the same style?

    python experiments/tgst_bandai/validity_breakdown.py DATA_DIR OUT.json [--trim 0.3]

For every reference clip g (content C, style S, not neutral) and the authors' protocol (root-local positions,
forward differences, a TRIM-second cut, g followed by its mirror as the style reference): E^style(x | g) and
(with --content) E^content(g, x) (means over windows / frames) for x = every clip of the SAME CONTENT in another style
("same content") and x = every clip of the SAME STYLE with another content ("same style"). Table 1's style
metric is valid when "same style" has the lower style error; its content metric when "same content" has the
lower content error. Prints the means over reference clips (each reference's mean over its x first), the
paired difference with its standard error over references, and per content / per style how often each wins.
"""
import argparse
import json
import pathlib
import sys

import numpy as np

from jaxgest import metrics
from jaxgest.runtime.errors import DataError
from jaxgest.motion.datasets import load_folder
from jaxgest.tgst.evaluate import NEUTRAL, _FeatureCache, get_protocol


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("data"), ap.add_argument("out")
    ap.add_argument("--trim", type=float, default=0.3)
    ap.add_argument("--content", action="store_true", help="also the content errors (exact DTW: slow)")
    a = ap.parse_args(argv[1:])
    proto = get_protocol("authors", a.trim)
    clips = load_folder(a.data, progress=False)
    fps = 60.0
    window = metrics.window_for_fps(fps)
    cache = _FeatureCache(proto)

    def feats(c, ref=False):
        try:
            f = cache(c, fps, ref)
        except DataError:
            return None
        return f if len(f[1]) >= window else None

    neutral = {n.lower() for n in NEUTRAL}
    refs = [c for c in clips if c.style.lower() not in neutral]
    rows = []
    for g in refs:
        fg, fg_ref = feats(g), feats(g, True)
        if fg is None or fg_ref is None:
            continue
        out = {"clip": g.path.name, "content": g.content, "style": g.style}
        for kind, pick in (("same_content", lambda x: x.content == g.content and x.style != g.style),
                           ("same_style", lambda x: x.style.lower() == g.style.lower() and x.content != g.content)):
            se, ce = [], []
            for x in clips:
                if x is g or not pick(x):
                    continue
                fx = feats(x)
                if fx is None:
                    continue
                se.append(metrics.style_error(fx[1], fg_ref[1], window)["mean"])
                if a.content:
                    ce.append(metrics.content_error(fg[0], fx[0])["mean"])
            out[kind] = {"style": float(np.mean(se)) if se else None, "content": float(np.mean(ce)) if ce else None,
                         "n": len(se)}
        if out["same_content"]["n"] and out["same_style"]["n"]:
            rows.append(out)
    res = {"data": pathlib.Path(a.data).name, "trim_seconds": a.trim, "references": len(rows), "per_reference": rows}
    for g in ("style", "content") if a.content else ("style",):
        sc = np.array([r["same_content"][g] for r in rows])
        ss = np.array([r["same_style"][g] for r in rows])
        d = ss - sc
        res[g] = {"same_content": float(sc.mean()), "same_style": float(ss.mean()),
                  "same_style_minus_same_content": float(d.mean()), "se": float(d.std(ddof=1) / np.sqrt(len(d))),
                  "same_style_lower": int((d < 0).sum())}
    for key in ("content", "style"):
        groups = {}
        for r in rows:
            groups.setdefault(r[key], []).append(r["same_style"]["style"] < r["same_content"]["style"])
        res[f"style_metric_valid_fraction_by_{key}"] = {k: f"{sum(v)}/{len(v)}" for k, v in sorted(groups.items())}
    with open(a.out, "w") as f:
        json.dump(res, f, indent=1)
    print(json.dumps({k: v for k, v in res.items() if k != "per_reference"}, indent=1))


if __name__ == "__main__":
    main(sys.argv)

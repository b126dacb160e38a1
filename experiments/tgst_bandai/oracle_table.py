"""Markdown tables of oracle_swap.py (and collage_bound.py) results, over the pairs every row evaluates.

    python experiments/tgst_bandai/oracle_table.py ORACLE_JSON [BOUND_JSON]

Per pair mode: each variant's mean content (m) and style (m/s) error over the pairs where "style as is" is
defined (its own frames hold one style window), the paired difference of the content error against the style
clip as is (mean +- standard error over pairs, pairs where the variant is lower) and the mean token distance
from the content token each output token replaces. BOUND_JSON adds the nearest-frame bound and the ground
truth's content error on the same pairs.
"""
import json
import sys

import numpy as np

LABELS = {
    "learned_soft": "learned soft swap (eq. 4)", "learned_hard": "learned hard swap (eq. 19)",
    "oracle_latent_hard": "oracle: nearest style token in latent space",
    "oracle_latent_soft_0.25": "oracle: softmax over latent distance, T = 0.25",
    "oracle_latent_soft_1": "oracle: softmax over latent distance, T = 1",
    "oracle_hands_hard": "oracle: style token with the nearest hand trajectory (16 frames)",
    "oracle_latent_frame": "oracle: nearest style latent frame (4 frames, no tokens)",
    "oracle_hands_frame": "oracle: style latent frame with the nearest hands (4 frames)",
    "content_roundtrip": "*content round trip (its own tokens)*", "style_roundtrip": "*style clip round trip*",
    "style_as_is": "*style as is*", "content_as_is": "*content as is*",
}


def main(argv):
    rep = json.loads(open(argv[1]).read())
    bound = json.loads(open(argv[2]).read()) if len(argv) > 2 else None
    for mode, r in rep["pairs"].items():
        recs = [p for p in r["per_pair"] if "errors" in p and "content" in p["errors"].get("style_as_is", {})]
        key = lambda p: (p["content"], p["style"])  # noqa: E731
        ref = np.array([p["errors"]["style_as_is"]["content"]["mean"] for p in recs])
        print(f"\n**{mode}** ({len(recs)} pairs)\n")
        print("| variant | content (m) | style (m/s) | content - style as is (m) | lower | token distance |")
        print("|---|---|---|---|---|---|")
        for name in recs[0]["errors"]:
            ce = np.array([p["errors"][name]["content"]["mean"] for p in recs])
            se = np.array([p["errors"][name]["style"]["mean"] for p in recs])
            d = ce - ref
            sem = d.std(ddof=1) / np.sqrt(len(d))
            td = [p["token_dist"][name] for p in recs if name in p["token_dist"]]
            tds = f"{np.mean(td):.2f}" if td else ""
            diff = "" if name == "style_as_is" else f"{d.mean():+.3f} +- {sem:.3f}"
            low = "" if name == "style_as_is" else f"{int((d < 0).sum())}/{len(d)}"
            print(f"| {LABELS.get(name, name)} | {ce.mean():.3f} | {se.mean():.3f} | {diff} | {low} | {tds} |")
        td = [p["token_dist"]["random_token"] for p in recs]
        print(f"| *random style token (chance)* | | | | | {np.mean(td):.2f} |")
        if bound is not None:
            b = {key(p): p for p in bound[mode]["per_pair"]}
            for k, lab in (("nearest_frame", "bound: nearest style frame per content frame (no model)"),
                           ("ground_truth", "*ground truth (content in the target style)*")):
                v = np.array([b[key(p)][k] for p in recs if k in b[key(p)]])
                d = v - np.array([b[key(p)]["style_as_is"] for p in recs if k in b[key(p)]])
                sem = d.std(ddof=1) / np.sqrt(len(d))
                print(f"| {lab} | {v.mean():.3f} | | {d.mean():+.3f} +- {sem:.3f} | {int((d < 0).sum())}/{len(d)} | |")


if __name__ == "__main__":
    sys.exit(main(sys.argv))

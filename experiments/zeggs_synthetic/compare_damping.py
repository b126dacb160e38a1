"""Paired comparison of two ``damping_diagnostic.py`` outputs on the same test clips.

Per clip, the temporal std of the generated root-frame joint velocities (and positions) divided by the real
clip's, in a window of frames; the difference B - A, mean and standard error over clips.

Usage: python experiments/zeggs_synthetic/compare_damping.py A.json B.json [--variant inference_init]
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def ratios(d: dict, variant: str, group: str, window: str) -> np.ndarray:
    pc = d["decay"]["per_clip"]
    return np.array([g[group][window] / r[group][window] for g, r in zip(pc[variant], pc["real"])])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--variant", default="inference_init")
    args = ap.parse_args(argv)
    a, b = (json.load(open(p)) for p in (args.a, args.b))
    print(f"| group, frames | A: {args.a} | B: {args.b} | B − A (± SE over clips) |\n|---|---:|---:|---:|")
    for group in ("local_velocities", "local_positions"):
        for window in a["decay"]["per_clip"]["real"][0][group]:
            ra, rb = ratios(a, args.variant, group, window), ratios(b, args.variant, group, window)
            d = rb - ra
            print(f"| {group}, {window} | {ra.mean():.3f} | {rb.mean():.3f} | "
                  f"{d.mean():+.3f} ± {d.std(ddof=1) / np.sqrt(len(d)):.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Measurable effects of blends and PCA edits (experiments/zeggs_synthetic).

Blend sweep / PCA edit outputs: mean hand speed (cm/s) and mean hand height above the root (cm) of every
generated clip, and of the style examples, so the sweep can be read as numbers. (The probe's controls,
random-init encoder and raw window statistics, are computed by ``jaxgest zeggs evaluate`` itself.)

Usage: python extra_measures.py --workdir W --data DIR --out-dir OUT --json OUT.json
"""

from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np

from jaxgest import metrics
from jaxgest.motion import bvh
from jaxgest.motion import kinematics as K
from jaxgest.zeggs.evaluate import _hand_indices


def motion_stats(m) -> dict:
    pos = K.forward_kinematics(m)
    hands = _hand_indices(m)
    speed = metrics.hand_speed(pos, m.fps, hands)
    root = m.skeleton.index(m.skeleton.names[0])
    height = pos[:, hands, 1] - pos[:, root:root + 1, 1]
    return {"hand_speed_cm_s": float(np.mean(speed)), "hand_height_above_root_cm": float(np.mean(height))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--out-dir", required=True)
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    out = pathlib.Path(args.out_dir)
    outputs = {p.stem: motion_stats(bvh.load(p)) for p in sorted(out.glob("blend_*.bvh")) + sorted(
        out.glob("pca0_*.bvh"))}
    examples = {p.stem: motion_stats(bvh.load(pathlib.Path(args.data) / f"{p.stem}.bvh"))
                for p in (pathlib.Path("apology_energetic_0"), pathlib.Path("apology_sad_0"),
                          pathlib.Path("apology_neutral_0"))}
    result = {"generated_outputs": outputs, "style_examples": examples}
    pathlib.Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

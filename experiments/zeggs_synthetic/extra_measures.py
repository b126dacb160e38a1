"""Controls for the style probe, and measurable effects of blends and PCA edits (experiments/zeggs_synthetic).

* Probe controls on the same held-out split and windows as ``jaxgest zeggs evaluate``: (a) the same
  ridge probe on hand-made window statistics (per-channel mean and std of the normalised pose features,
  2P dims) -- what a probe gets without any learned encoder; (b) the style encoder at its random
  initialisation (same architecture, seed 0) -- what the architecture gives before training.
* Blend sweep / PCA edit outputs: mean hand speed (cm/s) and mean hand height above the root (cm) of
  every generated clip, and of the two style examples, so the sweep can be read as numbers.

Usage: python extra_measures.py --workdir W --data DIR --out-dir OUT --json OUT.json
"""

from __future__ import annotations

import argparse
import json
import pathlib

import jax
import numpy as np

from jaxgest import metrics
from jaxgest.motion import bvh
from jaxgest.motion import kinematics as K
from jaxgest.motion.datasets import load_folder
from jaxgest.zeggs.evaluate import _hand_indices, _split_by_style, style_windows
from jaxgest.zeggs.inference import ZeggsModel_
from jaxgest.zeggs.steps import init_params


def probe_with(embed, train, test):
    def run(group):
        xs, ys = [], []
        for c in group:
            e = embed(c)
            xs.append(e)
            ys.extend([c.style] * len(e))
        return np.concatenate(xs), np.asarray(ys)

    xtr, ytr = run(train)
    xte, yte = run(test)
    return float(metrics.linear_probe_accuracy(xtr, ytr, xte, yte))


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

    clips = load_folder(args.data)
    train, test = _split_by_style(clips, args.seed)
    model = ZeggsModel_(args.workdir)
    window_s = 4.0
    n = int(window_s * model.cfg.fps)

    def raw_stats(c):
        f = model.style_features(c.motion)
        starts = list(range(0, max(1, len(f) - n + 1), n)) or [0]
        return np.stack([np.concatenate([f[s:s + n].mean(0), f[s:s + n].std(0)]) for s in starts])

    trained_acc = probe_with(lambda c: style_windows(model, c, window_s), train, test)
    random_model = ZeggsModel_(args.workdir)
    random_model.params = init_params(model.cfg, jax.random.PRNGKey(args.seed))
    random_acc = probe_with(lambda c: style_windows(random_model, c, window_s), train, test)
    raw_acc = probe_with(raw_stats, train, test)
    styles = sorted({c.style for c in clips})

    out = pathlib.Path(args.out_dir)
    outputs = {p.stem: motion_stats(bvh.load(p)) for p in sorted(out.glob("blend_*.bvh")) + sorted(
        out.glob("pca0_*.bvh"))}
    examples = {p.stem: motion_stats(bvh.load(pathlib.Path(args.data) / f"{p.stem}.bvh"))
                for p in (pathlib.Path("apology_energetic_0"), pathlib.Path("apology_sad_0"),
                          pathlib.Path("apology_neutral_0"))}
    result = {
        "probe": {"trained_encoder": trained_acc, "random_init_encoder": random_acc,
                  "window_mean_std_features": raw_acc, "chance": 1.0 / len(styles)},
        "generated_outputs": outputs, "style_examples": examples,
    }
    pathlib.Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

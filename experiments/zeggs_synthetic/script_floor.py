"""How far real motion of the same content and style is from the test clips when only the script differs.

    python experiments/zeggs_synthetic/script_floor.py --data D --others D1 D2 ... [--json OUT]

The Fréchet "floor" of `jaxgest zeggs evaluate` compares the two halves of one dataset (its style split:
the train half against the test half, same script seed). Held-out scripts change more than the split does:
every synthetic clip is 10 s with a handful of strokes, so its script shapes its pose and velocity
statistics. For the test clips of D (the same split as `evaluate`), this computes the Fréchet distance
(root-frame joint positions and velocities per frame, `jaxgest.zeggs.evaluate.motion_statistics_features`)
of the real clips of the same contents and styles from each other script seed (folders written by
`jaxgest synth --seed K`), beside the floor; a model's generated distance on D can be read against both.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def frechet(x: np.ndarray, y: np.ndarray) -> float:
    """Fréchet distance between the per-frame feature sets ``x`` and ``y`` (Gaussian statistics)."""
    from jaxgest import metrics

    return metrics.frechet_distance_from_statistics(*metrics.gaussian_statistics(x), *metrics.gaussian_statistics(y))


def test_split(folder, seed: int = 0) -> tuple[list, list, np.ndarray, float]:
    """(train clips, test clips, the test clips' features, the floor) of a folder, split as `evaluate`."""
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import evaluate as ev

    clips = [c for c in load_folder(folder) if c.audio is not None]
    train, test = ev._split_by_style(clips, seed)
    real = np.concatenate([ev.motion_statistics_features(c.motion) for c in test])
    floor = frechet(np.concatenate([ev.motion_statistics_features(c.motion) for c in train]), real)
    return train, test, real, floor


def other_script_distance(test, real: np.ndarray, folder) -> float:
    """Fréchet distance to ``real`` of the clips of ``folder`` with the test clips' contents and styles."""
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import evaluate as ev

    by_label = {(c.content, c.style): c for c in load_folder(folder)}
    return frechet(np.concatenate([ev.motion_statistics_features(by_label[(c.content, c.style)].motion)
                                   for c in test]), real)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True), ap.add_argument("--others", nargs="+", required=True)
    ap.add_argument("--seed", type=int, default=0), ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)

    _, test, real, floor = test_split(a.data, a.seed)
    out = {"data": a.data, "test_clips": len(test), "floor": floor,
           "other_scripts": {folder: other_script_distance(test, real, folder) for folder in a.others}}
    v = np.array(list(out["other_scripts"].values()))
    print(f"{a.data}: {len(test)} test clips; floor (train half vs test half) {floor:.0f}")
    for k, x in out["other_scripts"].items():
        print(f"  same contents and styles, script of {k}: {x:.0f} ({x / floor:.2f}x the floor)")
    print(f"  over {len(v)} other scripts: median {np.median(v):.0f} ({np.median(v) / floor:.2f}x), "
          f"range {v.min():.0f}-{v.max():.0f} ({v.min() / floor:.2f}-{v.max() / floor:.2f}x)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

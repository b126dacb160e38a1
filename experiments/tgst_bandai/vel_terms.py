"""Table of autoencoder variants from their `diagnose.py` JSONs, seeds averaged per clip, paired against a base.

    python experiments/tgst_bandai/vel_terms.py RESULTS_DIR BASE VARIANT [VARIANT ...] [--seeds 0,1] [--suffix _tube]

Each NAME reads ``RESULTS_DIR/diag_NAME_sS.json`` for every seed S; with ``--suffix _tube`` the round trips come
from ``diag_NAME_sS_tube.json`` (written with ``--contact-tolerance``), the angles still from the first file. Columns: held-out angle (mean over clips and seeds) and its paired difference to PCA-16
and to BASE; arm speed ratio overall and on frames 0-5 (mean over clips) and its paired difference to BASE;
the per-joint interior speed ratio range; the world and authors' round-trip style error. Paired = per clip
(seeds averaged) variant minus reference, mean +- SE over clips (clips lower).
"""
from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np


def paired(a, b) -> str:
    d = np.asarray(a, float) - np.asarray(b, float)
    return f"{d.mean():+.3f} +- {d.std(ddof=1) / np.sqrt(len(d)):.3f} ({int((d < 0).sum())}/{len(d)})"


def load(res: pathlib.Path, name: str, seeds, suffix: str) -> dict:
    # angles (and the baselines) from the run without the suffix: the floor contact moves the root only
    # (a run diagnosed only with the suffix, with TRAIN_DIR, has its angles and baselines in that file)
    angles = [json.loads((res / f"diag_{name}_s{s}.json" if (res / f"diag_{name}_s{s}.json").is_file()
                          else res / f"diag_{name}_s{s}{suffix}.json").read_text())["angle_deg"] for s in seeds]
    runs = [json.loads((res / f"diag_{name}_s{s}{suffix}.json").read_text()) for s in seeds]
    clips = runs[0]["clips"]
    assert all(r["clips"] == clips for r in runs), f"{name}: seeds evaluated on different clips"
    rt = [{c["clip"]: c for c in r["roundtrip"]["clips"]} for r in runs]
    common = sorted(set.intersection(*(set(x) for x in rt)))
    joints = {k: np.mean([r["roundtrip"]["joint_interior_ratio"][k] for r in runs]) for k in
              runs[0]["roundtrip"]["joint_interior_ratio"]}
    return {
        "angle": np.mean([a["autoencoder"]["per_clip"] for a in angles], axis=0),
        "pca16": np.asarray(angles[0]["pca16"]["per_clip"]),
        "speed": np.array([np.mean([x[c]["speed_ratio"] for x in rt]) for c in common]),
        "speed05": np.array([np.mean([x[c]["speed_ratio_0_5"] for x in rt]) for c in common]),
        "speed_clips": common,
        "joints": joints,
        "style_world": np.mean([r["roundtrip"]["style_world"] for r in runs]),
        "style_authors": np.mean([r["roundtrip"]["style_authors"] for r in runs]),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results"), ap.add_argument("base"), ap.add_argument("variants", nargs="+")
    ap.add_argument("--seeds", default="0,1"), ap.add_argument("--suffix", default="")
    a = ap.parse_args(argv)
    res, seeds = pathlib.Path(a.results), [int(s) for s in a.seeds.split(",")]
    base = load(res, a.base, seeds, a.suffix)
    print("| run | held-out angle (deg) | - PCA-16 (paired) | - base (paired) | arm speed ratio overall / 0-5 "
          "| - base, overall (paired) | per-joint interior ratio (min-max) | round-trip style world / authors (m/s) |")
    print("|---|---|---|---|---|---|---|---|")
    for name in [a.base] + a.variants:
        v = load(res, name, seeds, a.suffix)
        assert v["speed_clips"] == base["speed_clips"]
        j = list(v["joints"].values())
        print(f"| {name} | {v['angle'].mean():.2f} | {paired(v['angle'], v['pca16'])} | "
              f"{paired(v['angle'], base['angle'])} | {v['speed'].mean():.3f} / {v['speed05'].mean():.3f} | "
              f"{paired(v['speed'], base['speed'])} | {min(j):.2f}-{max(j):.2f} | "
              f"{v['style_world']:.3f} / {v['style_authors']:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

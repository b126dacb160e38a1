"""Does a seed's round trip on its *training* clips predict its round trip on the held-out clips?

    python experiments/tgst_bandai/seed_select.py RESULTS_DIR NAME --seeds 0,1,2,3,4,5 [--pick K]
        [--eval-dir out/data_eval] [--compare NAME2] [--spread-only]

Reads ``RESULTS_DIR/diag_NAME_sS_train_tube.json`` (``diagnose.py`` run on the training clips, no held-out
data) and ``RESULTS_DIR/diag_NAME_sS_tube.json`` / ``diag_NAME_sS.json`` (held-out clips). Prints per seed the
training and held-out arm speed ratio and mean angle, the rank correlation of training vs held-out speed over
seeds, and the selection rule "train K seeds, keep the one whose training-clip speed ratio is closest to 1"
evaluated over every K-subset of the seeds: how often the kept seed meets the held-out criteria (speed within
5 %, angle below PCA-16), against how often a seed drawn at random does.

With ``--eval-dir`` (the held-out clips the ``_tube`` files were measured on) it also asks where the seed
spread of the held-out speed sits: per seed, the speed ratio as ``diagnose.py`` aggregates it (mean over clips
of the per-clip ratio), as the ratio of pooled mean speeds (output arm speed summed over every frame of every
clip / the input's; the input speeds are recomputed from the clips as ``diagnose.roundtrip`` does) and as the
median clip; the clips that carry the spread (largest standard deviation over seeds) with their input arm
speed; the seed means without them; and the split-half agreement of the seed means (random halves of the
clips, correlation over seeds of the two halves' means: near 1 if a seed's speed is a property of the model,
near 0 if it is a property of a few clips). ``--compare NAME2`` prints the same aggregates for another run.
"""
from __future__ import annotations

import argparse
import itertools
import json
import pathlib

import numpy as np


def rank_correlation(a, b) -> float:
    """Spearman's rho (no ties expected for continuous measurements)."""
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results"), ap.add_argument("name")
    ap.add_argument("--seeds", default="0,1,2,3,4,5"), ap.add_argument("--pick", type=int, default=3)
    ap.add_argument("--eval-dir", default=None), ap.add_argument("--compare", default=None)
    ap.add_argument("--spread-only", action="store_true", help="only the --eval-dir part (no training-clip files)")
    a = ap.parse_args(argv)
    res, seeds = pathlib.Path(a.results), [int(s) for s in a.seeds.split(",")]
    if a.spread_only:
        spread_report(res, [a.name] + ([a.compare] if a.compare else []), seeds, pathlib.Path(a.eval_dir))
        return 0
    rows = []
    for s in seeds:
        tr = json.loads((res / f"diag_{a.name}_s{s}_train_tube.json").read_text())
        ho = json.loads((res / f"diag_{a.name}_s{s}_tube.json").read_text())
        ang = json.loads((res / f"diag_{a.name}_s{s}.json").read_text())["angle_deg"]
        rows.append({
            "seed": s,
            "train_speed": tr["roundtrip"]["speed_ratio"], "train_angle": tr["angle_deg"]["autoencoder"]["mean"],
            "heldout_speed": ho["roundtrip"]["speed_ratio"], "heldout_speed_0_5": ho["roundtrip"]["speed_ratio_0_5"],
            "heldout_angle": ang["autoencoder"]["mean"], "pca16": ang["pca16"]["mean"],
        })
    print("| seed | training clips: speed / angle (deg) | held-out: speed overall / 0-5 / angle (deg) | "
          "held-out criteria (speed within 5 %, angle < PCA-16) |")
    print("|---|---|---|---|")
    for r in rows:
        r["meets"] = bool(abs(r["heldout_speed"] - 1) <= 0.05 and abs(r["heldout_speed_0_5"] - 1) <= 0.05
                          and r["heldout_angle"] < r["pca16"])
        print(f"| {r['seed']} | {r['train_speed']:.3f} / {r['train_angle']:.2f} | {r['heldout_speed']:.3f} / "
              f"{r['heldout_speed_0_5']:.3f} / {r['heldout_angle']:.2f} | {'yes' if r['meets'] else 'no'} |")
    ts, hs = [r["train_speed"] for r in rows], [r["heldout_speed"] for r in rows]
    print(f"\nrank correlation, training vs held-out speed over {len(rows)} seeds: {rank_correlation(ts, hs):+.2f}"
          f"; Pearson {np.corrcoef(ts, hs)[0, 1]:+.2f}")
    ta, ha = [r["train_angle"] for r in rows], [r["heldout_angle"] for r in rows]
    print(f"rank correlation, training vs held-out angle: {rank_correlation(ta, ha):+.2f}")
    picks = []
    for subset in itertools.combinations(rows, a.pick):
        best = min(subset, key=lambda r: abs(r["train_speed"] - 1))
        picks.append(best)
    kept = np.mean([p["meets"] for p in picks])
    print(f"keep the seed of {a.pick} closest to 1x on its training clips, over all {len(picks)} subsets: meets the "
          f"held-out criteria in {kept:.0%} (a random seed: {np.mean([r['meets'] for r in rows]):.0%}); kept seed's "
          f"held-out speed {np.mean([p['heldout_speed'] for p in picks]):.3f} (random seed {np.mean(hs):.3f})")
    if a.eval_dir:
        spread_report(res, [a.name] + ([a.compare] if a.compare else []), seeds, pathlib.Path(a.eval_dir))
    return 0


def input_arm_speeds(eval_dir: pathlib.Path) -> dict:
    """Per held-out clip: (mean world arm-joint speed in m/s, number of speed frames), as diagnose.roundtrip."""
    from diagnose import arm_speeds
    from jaxgest.motion import datasets

    out = {}
    for clip in datasets.load_folder(eval_dir, progress=False):
        sx = arm_speeds(clip.motion)
        out[clip.path.name] = (float(sx.mean()), len(sx))
    return out


def spread_report(res: pathlib.Path, names, seeds, eval_dir: pathlib.Path, top: int = 3) -> None:
    speed_in = input_arm_speeds(eval_dir)
    for name in names:
        per = [json.loads((res / f"diag_{name}_s{s}_tube.json").read_text())["roundtrip"]["clips"] for s in seeds]
        clips = [c["clip"] for c in per[0]]
        ratio = np.array([[c["speed_ratio"] for c in p] for p in per])  # (seeds, clips)
        sin = np.array([speed_in[c][0] for c in clips])
        n = np.array([speed_in[c][1] for c in clips])
        pooled = (ratio * sin * n).sum(1) / (sin * n).sum()
        print(f"\n{name}, held-out arm speed ratio per seed ({len(clips)} clips):")
        print("| aggregate | " + " | ".join(f"s{s}" for s in seeds) + " | range |")
        print("|---|" + "---|" * (len(seeds) + 1))
        for label, v in (("mean of per-clip ratios (diagnose.py)", ratio.mean(1)),
                         ("ratio of pooled mean speeds", pooled), ("median clip", np.median(ratio, 1))):
            print(f"| {label} | " + " | ".join(f"{x:.3f}" for x in v) + f" | {v.min():.3f}-{v.max():.3f} |")
        worst = np.argsort(-ratio.std(0))[:top]
        rest = np.delete(ratio, worst, axis=1).mean(1)
        print(f"| mean of per-clip ratios without the {top} clips below | " + " | ".join(f"{x:.3f}" for x in rest)
              + f" | {rest.min():.3f}-{rest.max():.3f} |")
        print(f"clips with the largest spread over seeds (input arm speed, m/s; median clip "
              f"{np.median(sin):.3f}):")
        for i in worst:
            print(f"  {clips[i]}: input {sin[i]:.3f}; ratio per seed " + " ".join(f"{x:.2f}" for x in ratio[:, i]))
        rng = np.random.default_rng(0)
        cors = []
        for _ in range(2000):
            p = rng.permutation(len(clips))
            h = len(clips) // 2
            cors.append(np.corrcoef(ratio[:, p[:h]].mean(1), ratio[:, p[h:]].mean(1))[0, 1])
        cors = np.array(cors)
        print(f"split-half agreement of the seed means (2,000 random halves): correlation {cors.mean():+.2f} "
              f"(10-90 % {np.percentile(cors, 10):+.2f} .. {np.percentile(cors, 90):+.2f})")


if __name__ == "__main__":
    raise SystemExit(main())

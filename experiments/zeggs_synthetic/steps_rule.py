"""The rule of "Longer training of the default" (README): the same seed's runs at 8k, 16k (and 24k) steps,
from the JSONs each run's ``eval_run.sh`` wrote (or their ``window_runs.json`` entries):

    python experiments/zeggs_synthetic/steps_rule.py out ipz20_8k,ipz20_16k[,ipz20_24k] \
        ipz20_8k_s1,ipz20_16k_s1[,ipz20_24k_s1] [--json out/steps_rule.json]

Each argument after ``out`` is one seed's runs in order of training length. Per run: pooled style probe,
its paired difference to the raw statistics (SE over the 672 clips), held-out leakage z and held-out
BeatAlign z. Per seed: the paired probe difference of each longer run against the first one, per dataset
(16 units, SE over units, ddof 1); over seeds, the second run minus the first for the probe (its gap to the
raw statistics moves by as much: they do not depend on the weights), held-out Fréchet x floor and held-out
BeatAlign - shuffled. The gap **shrinks** if in every seed the second run minus the first is > 0 at z >= 2; it **closes** at a step count if there, in every seed, probe - raw statistics >= 0, held-out
leakage z >= 3 and held-out BeatAlign z >= 2.
"""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np

from initial_pose_table import load
from seed_rule import measures


def mean_se(d) -> dict:
    """Mean, SE (ddof 1), z (None when SE = 0) and n of the differences ``d``."""
    d = np.asarray(d, np.float64)
    se = float(d.std(ddof=1) / np.sqrt(len(d)))
    return {"mean": float(d.mean()), "standard_error": se, "z": float(d.mean() / se) if se > 0 else None,
            "n": int(len(d))}


def run_measures(out: Path, run: str) -> dict:
    m = measures(out, run)
    st = load(out, f"eval_pooled_{run}")["probe_pooled"]["style"]
    raw = st["trained_minus"]["raw_statistics"]
    eh = load(out, f"eval_{run}_heldout")  # read by measures() too; a few kB
    f = eh["frechet_distance"]
    m.update(minus_raw=raw["mean"], minus_raw_se=raw["standard_error"],
             heldout_frechet_x_floor=f["generated_vs_real"] / f["real_train_vs_real_test"],
             heldout_beat=eh["beat_alignment"]["generated_vs_control"]["mean"],
             units=dict(zip(st["trained"]["unit_names"], st["trained"]["per_unit"])))
    return m


def paired_units(a: dict, b: dict) -> dict:
    """``b - a`` per dataset (the same 16 datasets in both), mean, SE (ddof 1) and z."""
    if set(a) != set(b):
        raise SystemExit("steps_rule: the two runs were probed on different datasets")
    return mean_se([b[k] - a[k] for k in sorted(a)])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("seeds", nargs="+", help="per seed: comma-separated runs in order of training length")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    seeds = [s.split(",") for s in a.seeds]
    res = []
    print("| seed | run | pooled style probe | − raw statistics (± SE) | − first run, per dataset (± SE, z) "
          "| held-out leakage z | held-out BeatAlign z |")
    print("|---:|---|---:|---:|---:|---:|---:|")
    for runs in seeds:
        ms = [run_measures(a.out, r) for r in runs]
        suffix = re.search(r"_s(\d+)$", runs[0])
        i = int(suffix.group(1)) if suffix else 0  # the training seed, from the run name (no suffix: seed 0)
        for j, (r, m) in enumerate(zip(runs, ms)):
            m["run"], m["seed"] = r, i
            m["vs_first"] = paired_units(ms[0]["units"], m["units"]) if j else None
            v = m["vs_first"]
            vs = f"{v['mean']:+.3f} ± {v['standard_error']:.3f} (z {v['z'] or 0:.1f})" if v else "—"
            print(f"| {i} | {r} | {m['probe']:.3f} | {m['minus_raw']:+.3f} ± {m['minus_raw_se']:.3f} | {vs} "
                  f"| {m['leak_z']:.1f} | {m['beat_z']:.1f} |")
        res.append(ms)
    shrinks = all(len(ms) > 1 and ms[1]["vs_first"]["mean"] > 0 and (ms[1]["vs_first"]["z"] or 0) >= 2
                  for ms in res)
    closes = {}
    for j in range(1, min(len(ms) for ms in res)):
        closes[seeds[0][j]] = all(ms[j]["minus_raw"] >= 0 and ms[j]["leak_z"] >= 3 and ms[j]["beat_z"] >= 2
                                  for ms in res)
    print(f"\nshrinks with training (second run − first > 0 at z >= 2 in every seed): {shrinks}")
    for r, c in closes.items():
        print(f"closes at {r} (probe − raw >= 0, leakage z >= 3, BeatAlign z >= 2 in every seed): {c}")
    over = {}
    if len(res) > 1 and all(len(ms) > 1 for ms in res):
        print("\nsecond run − first, over seeds (SE over seeds, ddof 1):")
        for k in ("probe", "heldout_frechet_x_floor", "heldout_beat"):
            d = [ms[1][k] - ms[0][k] for ms in res]
            over[k] = {"per_seed": d, **mean_se(d)}
            o = over[k]
            print(f"  {k}: {o['mean']:+.3f} ± {o['standard_error']:.3f} (z {o['z'] or 0:.1f}); per seed "
                  + " ".join(f"{x:+.3f}" for x in d))
    if a.json:
        for ms in res:
            for m in ms:
                m.pop("units")
        a.json.write_text(json.dumps({"seeds": res, "shrinks": shrinks, "closes": closes, "over_seeds": over},
                                     indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

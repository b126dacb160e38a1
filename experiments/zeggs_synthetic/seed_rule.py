"""The decision rule for seeds 3 and 4 (README, "Seeds 3 and 4 of the default and of the mean-pose source"),
evaluated from the JSONs each run's ``eval_run.sh`` wrote (or their ``window_runs.json`` entries):

    python experiments/zeggs_synthetic/seed_rule.py out e64_8k,e64_8k_s1,e64_8k_s2,e64_8k_s3,e64_8k_s4 \
        ipz20_8k,ipz20_8k_s1,ipz20_8k_s2,ipz20_8k_s3,ipz20_8k_s4 [--new 3,4] [--json out/seed_rule.json]

The two lists pair seed by seed (default, candidate). For the seeds in ``--new`` (positions in the lists,
default the last two): (a) held-out BeatAlign - shuffled at z >= 2, (c) held-out leakage contrast (another
style - same style other content, the one held-out dataset) at z >= 3, each for the candidate; (b) over
all seeds the paired pooled-probe difference (candidate - default) has mean > 0 at z >= 2 (SE over seeds,
ddof 1), and in no new seed is the candidate more than 0.02 below the default.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from initial_pose_table import load


def measures(out: Path, run: str) -> dict:
    eh = load(out, f"eval_{run}_heldout")
    b = eh["beat_alignment"]["generated_vs_control"]
    return {"probe": load(out, f"eval_pooled_{run}")["probe_pooled"]["style"]["trained"]["accuracy"],
            "beat_z": b["mean"] / b["standard_error"],
            "leak_z": eh["leakage"]["contrasts"]["other_style - same_style_other_content"]["z"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("default")
    ap.add_argument("candidate")
    ap.add_argument("--new", default=None, help="comma-separated positions of the new seeds (default: last two)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    dflt, cand = a.default.split(","), a.candidate.split(",")
    if len(dflt) != len(cand):
        raise SystemExit("seed_rule: the two run lists must pair seed by seed (same length)")
    new = [int(i) for i in a.new.split(",")] if a.new else [len(cand) - 2, len(cand) - 1]
    md, mc = [measures(a.out, r) for r in dflt], [measures(a.out, r) for r in cand]
    diff = np.array([c["probe"] - d["probe"] for c, d in zip(mc, md)])
    se = float(diff.std(ddof=1) / np.sqrt(len(diff)))
    z = float(diff.mean() / se) if se > 0 else float("inf")
    print("| seed | default probe | candidate probe | candidate - default | candidate held-out BeatAlign z | "
          "candidate held-out leakage z |")
    print("|---:|---:|---:|---:|---:|---:|")
    for i, (d, c) in enumerate(zip(md, mc)):
        print(f"| {i}{' (new)' if i in new else ''} | {d['probe']:.3f} | {c['probe']:.3f} | {c['probe'] - d['probe']:+.3f} "
              f"| {c['beat_z']:.1f} | {c['leak_z']:.1f} |")
    a_ok = all(mc[i]["beat_z"] >= 2 for i in new)
    c_ok = all(mc[i]["leak_z"] >= 3 for i in new)
    b_ok = diff.mean() > 0 and z >= 2 and all(diff[i] >= -0.02 for i in new)
    print(f"\npaired probe difference over {len(diff)} seeds: {diff.mean():+.3f} +- {se:.3f} (z {z:.1f})")
    print(f"(a) BeatAlign z >= 2 in new seeds: {a_ok}; (b) probe: {b_ok}; (c) leakage z >= 3 in new seeds: {c_ok}")
    print("rule:", "ADOPT" if a_ok and b_ok and c_ok else "NOT ADOPTED")
    if a.json:
        a.json.write_text(json.dumps({"default": dict(zip(dflt, md)), "candidate": dict(zip(cand, mc)),
                                      "probe_difference": {"mean": float(diff.mean()), "standard_error": se, "z": z},
                                      "a": a_ok, "b": b_ok, "c": c_ok, "adopt": a_ok and b_ok and c_ok}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

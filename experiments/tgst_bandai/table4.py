"""Table 4 analogue: soft swap with each loss term switched off, intra and inter pairs pooled (as the paper).

    python experiments/tgst_bandai/table4.py RESULTS_DIR [FULL_PREFIX] [--seeds 0,1,2]

Reads FULL_PREFIX_{intra,inter}_s<k>.json (full loss, seed k; FULL_PREFIX default "eval") and
eval_ablate_{intra,inter}_s<term>.json (seed 0) / eval_ablate_{intra,inter}_s<term>_<k>.json (seed k > 0),
written by eval_seeds.py; prints the averages over the pooled pairs of mean / worst / w25 (each pair's errors
averaged over the seeds) and the paired difference of the per-pair mean errors against the full loss (mean
+- standard error over pairs). With several seeds, also each seed's difference (mean over pairs) and the
number of seeds where the removal raises the error. Paper values in brackets. Default seeds: 0.
"""
import json
import pathlib
import sys

import numpy as np

STATS = ("mean", "worst", "w25")
PAPER = {"identity": (0.216, 0.495, 0.36, 0.59, 1.26, 1.09), "cyclic": (0.208, 0.509, 0.356, 0.696, 1.5, 1.26),
         "structure": (0.198, 0.488, 0.338, 0.709, 1.54, 1.3), "appearance": (0.201, 0.491, 0.344, 0.708, 1.53, 1.29),
         "full": (0.203, 0.491, 0.344, 0.689, 1.49, 1.26)}


def pooled(folder, names):
    out = {}
    for n in names:
        r = json.loads((folder / n).read_text())
        for p in r["per_pair"]:
            e = p.get("errors", {}).get("soft")
            if e and "skipped" not in e:
                out[(r["pairs"], p["content"], p["style"])] = e
    return out


def averaged(per_seed):
    """Pairs present in every seed -> their errors averaged over the seeds (same nesting)."""
    keys = set.intersection(*(set(d) for d in per_seed))
    return {k: {g: {s: float(np.mean([d[k][g][s] for d in per_seed])) for s in STATS} for g in ("content", "style")}
            for k in keys}


def main(argv):
    seeds = ["0"]
    if "--seeds" in argv:
        i = argv.index("--seeds")
        seeds = argv[i + 1].split(",")
        argv = argv[:i] + argv[i + 2:]
    folder = pathlib.Path(argv[1])
    full = argv[2] if len(argv) > 2 else "eval"
    per_seed = {"full": [pooled(folder, [f"{full}_intra_s{k}.json", f"{full}_inter_s{k}.json"]) for k in seeds]}
    for t in ("identity", "cyclic", "structure", "appearance"):
        sfx = [t if k == "0" else f"{t}_{k}" for k in seeds]
        per_seed[t] = [pooled(folder, [f"eval_ablate_intra_s{x}.json", f"eval_ablate_inter_s{x}.json"]) for x in sfx]
    rows = {name: averaged(d) for name, d in per_seed.items()}
    if len(seeds) > 1:
        print(f"Seeds {', '.join(seeds)}: each pair's errors averaged over the seeds.\n")
    print("| Loss | " + " | ".join(f"{g} {s}" for g in ("content (m)", "style (m/s)") for s in STATS)
          + " | content diff vs full | style diff vs full | pairs |")
    print("|" + "---|" * 10)
    for name, d in rows.items():
        cells = []
        for gi, g in enumerate(("content", "style")):
            for si, s in enumerate(STATS):
                cells.append(f"{np.mean([e[g][s] for e in d.values()]):.3f} [{PAPER[name][gi * 3 + si]}]")
        keys = sorted(set(d) & set(rows["full"]))
        diffs = []
        for g in ("content", "style"):
            x = np.array([d[k][g]["mean"] - rows["full"][k][g]["mean"] for k in keys])
            diffs.append("-" if name == "full" else f"{x.mean():+.3f} +- {x.std(ddof=1) / np.sqrt(len(x)):.3f}")
        label = "L (all losses)" if name == "full" else f"w/o L_{name}"
        print(f"| {label} | " + " | ".join(cells + diffs) + f" | {len(keys)} |")
    if len(seeds) > 1:
        print("\nPer seed, removal minus full loss (mean over the pooled pairs; content m, style m/s):\n")
        print("| Loss | " + " | ".join(f"content s{k}" for k in seeds) + " | " + " | ".join(f"style s{k}" for k in seeds)
              + " | seeds raising content / style |")
        print("|" + "---|" * (2 * len(seeds) + 2))
        for name in ("identity", "cyclic", "structure", "appearance"):
            cols = {g: [] for g in ("content", "style")}
            for i in range(len(seeds)):
                d, f = per_seed[name][i], per_seed["full"][i]
                keys = sorted(set(d) & set(f))
                for g in cols:
                    cols[g].append(float(np.mean([d[k][g]["mean"] - f[k][g]["mean"] for k in keys])))
            up = [sum(x > 0 for x in cols[g]) for g in ("content", "style")]
            print(f"| w/o L_{name} | " + " | ".join(f"{x:+.3f}" for x in cols["content"] + cols["style"])
                  + f" | {up[0]}/{len(seeds)} / {up[1]}/{len(seeds)} |")


if __name__ == "__main__":
    main(sys.argv)

"""Table 4 analogue: soft swap with each loss term switched off, intra and inter pairs pooled (as the paper).

    python experiments/tgst_bandai/table4.py RESULTS_DIR [FULL_PREFIX]

Reads FULL_PREFIX_{intra,inter}_s0.json (full loss, seed 0; FULL_PREFIX default "eval") and eval_ablate_{intra,inter}_s<term>.json (written by
eval_seeds.py); prints the averages over the pooled pairs of mean / worst / w25 and the paired difference of
the per-pair mean errors against the full loss (mean +- standard error over pairs). Paper values in brackets.
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


def main(argv):
    folder = pathlib.Path(argv[1])
    full = argv[2] if len(argv) > 2 else "eval"
    rows = {"full": pooled(folder, [f"{full}_intra_s0.json", f"{full}_inter_s0.json"])}
    for t in ("identity", "cyclic", "structure", "appearance"):
        rows[t] = pooled(folder, [f"eval_ablate_intra_s{t}.json", f"eval_ablate_inter_s{t}.json"])
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


if __name__ == "__main__":
    main(sys.argv)

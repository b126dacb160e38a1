"""Training window T = 64 vs T = 128 over seeds: Fréchet (x floor), BeatAlign, leakage and probes from the
``jaxgest zeggs evaluate`` JSONs of each run, on the training scripts and the held-out scripts.

    python experiments/zeggs_synthetic/window_seeds.py out t64_k63,t64_s1,t64_s2 t128_k63,t128_s1,t128_s2 [--md FILE]

Each argument after the folder is a comma-separated list of run names (``out/eval_<name>.json`` and
``out/eval_<name>_heldout.json``; ``t64_k63`` / ``t128_k63`` are the seed-0 runs). Prints one row per run and
the mean ± SE over the seeds of each group (seeds are the independent units of the ordering claim).
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

ROWS = [
    ("Fréchet × floor", lambda d: d["frechet_distance"]["generated_vs_real"] / d["frechet_distance"]["real_train_vs_real_test"]),
    ("BeatAlign − shuffled", lambda d: d["beat_alignment"]["generated_vs_control"]["mean"]),
    ("leak (d)−(c) z", lambda d: d["leakage"]["contrasts"]["other_style - same_style_other_content"]["z"]),
    ("leak (e)−(c) z", lambda d: d["leakage"]["contrasts"]["zero - same_style_other_content"]["z"]),
    ("style probe", lambda d: d["probe"]["style"]["trained"]["accuracy"]),
    ("style − raw", lambda d: d["probe"]["style"]["trained"]["accuracy"] - d["probe"]["style"]["raw_statistics"]["accuracy"]),
    ("style − random", lambda d: d["probe"]["style"]["trained"]["accuracy"] - d["probe"]["style"]["random_init"]["accuracy"]),
    ("content probe", lambda d: d["probe"]["content"]["trained"]["accuracy"]),
]


def mean_se(xs):
    m = sum(xs) / len(xs)
    if len(xs) < 2:
        return m, float("nan")
    v = sum((x - m) ** 2 for x in xs) / (len(xs) - 1)
    return m, math.sqrt(v / len(xs))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("groups", nargs="+")
    ap.add_argument("--md")
    a = ap.parse_args()
    out = Path(a.out)
    lines = []
    for split, suffix in (("training scripts", ""), ("held-out scripts", "_heldout")):
        lines += [f"\n**{split}**\n", "| run | " + " | ".join(r[0] for r in ROWS) + " |",
                  "|---|" + "---:|" * len(ROWS)]
        for group in a.groups:
            vals = {r[0]: [] for r in ROWS}
            for name in group.split(","):
                f = out / f"eval_{name}{suffix}.json"
                if not f.is_file():
                    lines.append(f"| {name} | (missing {f.name}) |")
                    continue
                d = json.loads(f.read_text())
                row = []
                for label, fn in ROWS:
                    x = fn(d)
                    vals[label].append(x)
                    row.append(f"{x:.3f}" if abs(x) < 100 else f"{x:.0f}")
                lines.append(f"| {name} | " + " | ".join(row) + " |")
            n = len(next(iter(vals.values())))
            if n:
                cells = []
                for label, _ in ROWS:
                    m, se = mean_se(vals[label])
                    cells.append(f"**{m:.3f}** ± {se:.3f}" if not math.isnan(se) else f"**{m:.3f}**")
                lines.append(f"| mean ± SE ({n} seeds) | " + " | ".join(cells) + " |")
    text = "\n".join(lines)
    print(text)
    if a.md:
        Path(a.md).write_text(text + "\n")


if __name__ == "__main__":
    main()

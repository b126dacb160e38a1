"""Per-pair differences between two sets of Tables 2/3 evaluations (e.g. two autoencoders), per method.

    python experiments/tgst_bandai/compare_ae_tables.py RESULTS_DIR PREFIX_A PREFIX_B SEEDS [METHODS]

Reads PREFIX_{intra,inter}_s<k>.json for k in SEEDS (comma-separated) of both prefixes; per pair mode and
method (soft, hard, AdaIN, Avatar-net, round trip) the per-pair mean content / style errors averaged over
the seeds, then "B minus A" over the pairs both evaluate: mean +- standard error and the pairs where B is
lower. Prints markdown. METHODS (comma-separated, default all five): e.g. ``soft,hard`` when B evaluated only
the transformer's methods. SEEDS ``0,1,2:0`` pairs A's seeds 0, 1, 2 with B's seed 0 (A_SEEDS:B_SEEDS).
"""
import json
import pathlib
import sys

import numpy as np

from summarize import LABELS, per_pair

METHODS = ("soft", "hard", "adain", "avatarnet", "autoencoder")


def main(argv):
    folder, pa, pb = pathlib.Path(argv[1]), argv[2], argv[3]
    sa, _, sb = argv[4].partition(":")
    seeds = {pa: sa.split(","), pb: (sb or sa).split(",")}
    methods = tuple(argv[5].split(",")) if len(argv) > 5 else METHODS
    print(f"| pairs | method | content {pb} - {pa} (m) | {pb} lower | style {pb} - {pa} (m/s) | {pb} lower "
          "| pairs |")
    print("|---|---|---|---|---|---|---|")
    for mode in ("intra", "inter"):
        reps = {p: [json.loads((folder / f"{p}_{mode}_s{s}.json").read_text()) for s in seeds[p]] for p in (pa, pb)}
        for m in methods:
            d = {p: [per_pair(r, m) for r in reps[p]] for p in (pa, pb)}
            keys = sorted(set.intersection(*[set(x) for p in (pa, pb) for x in d[p]]))
            cells = [mode, LABELS[m]]
            for g in ("content", "style"):
                v = {p: np.array([np.mean([x[k][g]["mean"] for x in d[p]]) for k in keys]) for p in (pa, pb)}
                diff = v[pb] - v[pa]
                se = diff.std(ddof=1) / np.sqrt(len(diff))
                cells += [f"{diff.mean():+.3f} +- {se:.3f}", f"{int((diff < 0).sum())}/{len(diff)}"]
            print("| " + " | ".join(cells + [str(len(keys))]) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

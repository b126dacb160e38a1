"""The leakage report of `jaxgest zeggs evaluate` on several held-out script seeds, and pooled over them.

    python experiments/zeggs_synthetic/leakage_pooled.py --workdir W --datasets D1 D2 ... [--json OUT]

For each dataset (a `jaxgest synth --seed K` folder the model was not trained on):
`jaxgest.zeggs.probes.leakage` (fixed targets, the style embedding from each source, per-clip paired
contrasts). Pooled: the clip-weighted mean of the per-dataset means, with the stratified standard error
sqrt(sum n_i^2 se_i^2) / sum n_i (datasets independent; each dataset's clips are its units, as in the
single-dataset report). This is the leakage analogue of the pooled style probe (several datasets of held-out
scripts), not a redefinition of the single-dataset report, which is printed beside it.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

CONTRASTS = ("other_style - same_style_other_content", "zero - same_style_other_content")


def main(argv=None) -> int:
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import probes
    from jaxgest.zeggs.inference import load_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True), ap.add_argument("--datasets", nargs="+", required=True)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    model = load_model(a.workdir)
    reports = {}
    for d in a.datasets:
        rep = probes.leakage(model, [c for c in load_folder(d) if c.audio is not None])
        reports[d] = rep
        cells = [f"{c}: {rep['contrasts'][c]['mean']:+.4f} +- {rep['contrasts'][c]['standard_error']:.4f} "
                 f"(z {rep['contrasts'][c]['z']:.1f})" for c in CONTRASTS]
        print(f"{d} ({rep['clips']} clips): " + "; ".join(cells), flush=True)
    pooled = {}
    for c in CONTRASTS:
        n = np.array([r["contrasts"][c]["n"] for r in reports.values()], float)
        m = np.array([r["contrasts"][c]["mean"] for r in reports.values()])
        se = np.array([r["contrasts"][c]["standard_error"] for r in reports.values()])
        mean, s = float((n * m).sum() / n.sum()), float(np.sqrt((n ** 2 * se ** 2).sum()) / n.sum())
        pooled[c] = {"mean": mean, "standard_error": s, "z": mean / s, "clips": int(n.sum()),
                     "datasets_positive": int((m > 0).sum()), "datasets_z_ge_3": int(sum(
                         r["contrasts"][c]["z"] >= 3 for r in reports.values()))}
        print(f"pooled {c}: {mean:+.4f} +- {s:.4f} (z {mean / s:.1f}; {int(n.sum())} clips; positive in "
              f"{pooled[c]['datasets_positive']}/{len(m)} datasets, z >= 3 in {pooled[c]['datasets_z_ge_3']})")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"workdir": a.workdir, "datasets": reports, "pooled": pooled}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

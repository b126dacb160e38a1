"""Paired differences (later - earlier variant) per held-out window, mean ± standard error and z.

    python experiments/zeggs_fidelity/compare.py base loudness fk norm
"""

import json
import pathlib
import sys

import numpy as np

OUT = pathlib.Path(__file__).parent / "out"
names = sys.argv[1:]
runs = {n: json.loads((OUT / f"{n}.json").read_text()) for n in names if (OUT / f"{n}.json").is_file()}
terms = ("local_position", "world_position", "local_rotation", "fd_local_position")
print("| variant | train s | " + " | ".join(terms) + " |")
print("|---|---:|" + "---:|" * len(terms))
for n, r in runs.items():
    print(f"| {n} | {r['train_s']:.0f} | " + " | ".join(f"{r['heldout_mean'][t]:.4g}" for t in terms) + " |")
print()
print("| change | " + " | ".join(f"Δ {t} (± SE, z)" for t in terms) + " |")
print("|---|" + "---:|" * len(terms))
keys = list(runs)
for a, b in zip(keys, keys[1:]):
    cells = []
    for t in terms:
        d = np.asarray(runs[b]["heldout"][t]) - np.asarray(runs[a]["heldout"][t])
        se = d.std(ddof=1) / np.sqrt(len(d))
        cells.append(f"{d.mean():+.4g} ± {se:.2g} (z {d.mean() / se:+.1f})")
    print(f"| {a} → {b} | " + " | ".join(cells) + " |")

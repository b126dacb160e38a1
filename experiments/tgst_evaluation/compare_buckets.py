"""Paired per-pair differences between two `jaxgest tgst evaluate` reports of the same pairs.

    python experiments/tgst_evaluation/compare_buckets.py EXACT.json BUCKETED.json

For every method and error (mean statistic of each pair): the mean of (second - first) over the pairs both
reports evaluated, its standard error, the largest absolute per-pair difference and that difference relative
to the first report's mean; then the first report's paired method differences (for scale) and both reports'
swap diagnostics.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def _pairs(report):
    return {(r["content"], r["style"]): r for r in report["per_pair"]}


def main(first_path: str, second_path: str) -> None:
    a, b = (json.load(open(p)) for p in (first_path, second_path))
    pa, pb = _pairs(a), _pairs(b)
    keys = [k for k in pa if k in pb]
    print(f"{len(keys)} common pairs; protocol {a['protocol']['name']} / {b['protocol']['name']}; "
          f"bucket {a['bucket']} / {b['bucket']}")
    print(f"timing: {a['timing']} / {b['timing']}")
    print("| method | error | n | first mean | mean diff | se | max abs diff | max / mean |")
    print("|---|---|---|---|---|---|---|---|")
    for m in a["methods"]:
        for err in ("content", "style", "gt_content", "gt_style"):
            d, base = [], []
            for k in keys:
                ea, eb = pa[k]["errors"].get(m, {}), pb[k]["errors"].get(m, {})
                if err in ea and err in eb:
                    d.append(eb[err]["mean"] - ea[err]["mean"])
                    base.append(ea[err]["mean"])
            if len(d) < 2:
                continue
            d, base = np.array(d), np.array(base)
            se = d.std(ddof=1) / np.sqrt(len(d))
            print(f"| {m} | {err} | {len(d)} | {base.mean():.4f} | {d.mean():+.5f} | {se:.5f} | "
                  f"{np.abs(d).max():.5f} | {np.abs(d).max() / base.mean():.2%} |")
    methods = list(a["methods"])
    for x in methods[:1]:
        for y in methods[1:]:
            dd = [pa[k]["errors"][x]["style"]["mean"] - pa[k]["errors"][y]["style"]["mean"] for k in keys
                  if "style" in pa[k]["errors"].get(x, {}) and "style" in pa[k]["errors"].get(y, {})]
            if len(dd) > 1:
                print(f"first report, style {x} - {y}: {np.mean(dd):+.4f} +- {np.std(dd, ddof=1) / np.sqrt(len(dd)):.4f}"
                      f" (n {len(dd)})")
    print("swap diagnostics:", a.get("swap_diagnostics"), "/", b.get("swap_diagnostics"))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])

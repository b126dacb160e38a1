"""Table 1 analogue (metric validity) on the whole Bandai-Namco dataset, no model involved.

    python experiments/tgst_bandai/validity_full.py DATA_DIR OUT.json [--max-pairs N] [--seed S]

Inter-scenario pairs (content = a neutral clip, style = a clip of another content in another style,
ground truth = the content performed in that style), a seeded random subset of --max-pairs of them; calls
jaxgest.tgst.evaluate.metric_validity. The held-out run (run.sh, eval_intra.json) only has 2 contents,
so its Table 1 compares waving with guiding; this one averages over all 17 contents.
"""

from __future__ import annotations

import argparse
import sys

from jaxgest.tgst.evaluate import metric_validity
from jaxgest.training import write_json_atomic


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data")
    p.add_argument("json")
    p.add_argument("--max-pairs", type=int, default=300)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    report = metric_validity(a.data, pairs="inter", max_pairs=a.max_pairs, seed=a.seed)
    write_json_atomic(a.json, report)
    print(f"metric validity: {report['num_pairs']} pairs -> {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Reference row for Tables 2/3: "no transfer" (the content clip returned unchanged), same pairs and errors.

    python experiments/tgst_bandai/baseline_identity.py EVAL_DIR OUT_PREFIX

Writes OUT_PREFIX_intra.json and OUT_PREFIX_inter.json in the format of `jaxgest tgst evaluate` (method key
"soft" holds the identity's errors). Its content error is 0 by construction; its style error is what a
transfer has to beat to have moved the arm-velocity statistics towards the style clip at all.
"""

from __future__ import annotations

import sys

from jaxgest.tgst.evaluate import evaluate
from jaxgest.training import write_json_atomic


class Identity:
    def transfer(self, content, style, method="soft"):
        return content


def main(argv) -> int:
    data, prefix = argv[1:3]
    for pairs in ("intra", "inter"):
        report = evaluate("(identity)", data, pairs=pairs, methods=("soft",), model=Identity(), progress=False)
        report["note"] = "no transfer: the content clip itself is scored as the result"
        write_json_atomic(f"{prefix}_{pairs}.json", report)
        s = report["methods"]["soft"]
        print(f"identity {pairs}: content {s['content']['mean']:.3f} m, style {s['style']['mean']:.3f} m/s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

"""Tables 2/3 inputs with the soft swap (and/or hard swap) of another evaluation of the same pairs: copies
BASE_PREFIX_<pairs>_s<k>.json with the given methods (and the swap diagnostics) taken from
NEW_PREFIX_<pairs>_s<k>.json, so that summarize.py prints the four methods and the controls with the new
swap, e.g. the soft swap at another inference temperature or a retrained transformer.

    python experiments/tgst_bandai/merge_soft.py BASE_PREFIX NEW_PREFIX OUT_PREFIX SEEDS [METHODS]

SEEDS: comma-separated labels (both files per label); METHODS default ``soft``.
"""
import json
import sys


def main(argv):
    base, new, out, seeds = argv[1], argv[2], argv[3], argv[4].split(",")
    methods = argv[5].split(",") if len(argv) > 5 else ["soft"]
    for mode in ("intra", "inter"):
        for s in seeds:
            b = json.loads(open(f"{base}_{mode}_s{s}.json").read())
            n = json.loads(open(f"{new}_{mode}_s{s}.json").read())
            per = {(r["content"], r["style"]): r for r in n["per_pair"]}
            for m in methods:
                b["methods"][m] = n["methods"][m]
                for r in b["per_pair"]:
                    src = per[(r["content"], r["style"])]
                    if "errors" in r:
                        r["errors"][m] = src["errors"][m]
                    if "soft" in methods and "swap" in src:
                        r["swap"] = src["swap"]
            if "soft" in methods:
                b["swap_diagnostics"] = n.get("swap_diagnostics")
            b["merged_from"] = {"base": f"{base}_{mode}_s{s}.json", "new": f"{new}_{mode}_s{s}.json", "methods": methods}
            with open(f"{out}_{mode}_s{s}.json", "w") as f:
                json.dump(b, f, indent=1)


if __name__ == "__main__":
    sys.exit(main(sys.argv))

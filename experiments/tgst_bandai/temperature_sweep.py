"""Soft-swap temperature changed at inference only (no retraining): the trained transformers of WORKDIRs
evaluated with eq. 4's softmax divided by T, on the held-out pairs (authors' protocol).

    python experiments/tgst_bandai/temperature_sweep.py EVAL_DIR OUT_PREFIX TRIM T1,T2,... WORKDIR...
        [--seeds 0,1,2] [--pairs intra,inter]

Writes OUT_PREFIX_T<T>_<pairs>_s<k>.json (the JSON of `jaxgest tgst evaluate`, method soft only: the hard swap
does not depend on T). The model was trained at T = 1 (`model.swap_temperature`), so T != 1 is a change of the
trained function at inference: T > 1 blends more style tokens, T < 1 tends to the hard swap.
"""
import argparse
import dataclasses
import sys

from jaxgest.tgst.api import TGSTModel, load_model
from jaxgest.tgst.evaluate import evaluate
from jaxgest.runtime.training import write_json_atomic


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("eval_dir"), ap.add_argument("prefix"), ap.add_argument("trim", type=float)
    ap.add_argument("temperatures"), ap.add_argument("workdirs", nargs="+")
    ap.add_argument("--seeds", default=None)
    ap.add_argument("--pairs", default="intra,inter")
    a = ap.parse_args(argv[1:])
    labels = a.seeds.split(",") if a.seeds else [str(i) for i in range(len(a.workdirs))]
    for label, wd in zip(labels, a.workdirs):
        base = load_model(wd)
        for t in (float(x) for x in a.temperatures.split(",")):
            model = TGSTModel(dataclasses.replace(base.cfg, swap_temperature=t), base.params, wd,
                              config=base.config, steps=base.steps)
            for pairs in a.pairs.split(","):
                rep = evaluate(wd, a.eval_dir, pairs=pairs, methods=("soft",), trim_seconds=a.trim,
                               progress=False, model=model)
                rep["swap_temperature"] = t
                write_json_atomic(f"{a.prefix}_T{t:g}_{pairs}_s{label}.json", rep)
                print(label, t, pairs, rep["methods"]["soft"]["content"]["mean"], rep["methods"]["soft"]["style"]["mean"],
                      rep["timing"], flush=True)


if __name__ == "__main__":
    main(sys.argv)

"""`jaxgest tgst evaluate` of several workdirs and pair modes in ONE process (one compilation per bucket shape
for all of them: the seeds share the config, so the jitted transfers are reused).

    python experiments/tgst_bandai/eval_seeds.py EVAL_DIR OUT_PREFIX TRIM WORKDIR... [--pairs intra,inter] [--validity]
        [--methods soft,hard,adain,avatarnet,autoencoder]

Writes OUT_PREFIX_<pairs>_s<k>.json for the k-th workdir (the same JSON as `jaxgest tgst evaluate --json`),
methods soft, hard, adain, avatarnet, autoencoder (``--methods``: a subset, e.g. ``soft,hard`` for
transformer variants); the authors' protocol with a TRIM-second cut. ``--validity``:
the first workdir's intra report also holds the metric-validity table (Table 1, inter pairs), as
``jaxgest tgst evaluate --pairs intra --validity`` writes it.
"""
import argparse
import sys

from jaxgest.tgst.evaluate import evaluate, metric_validity
from jaxgest.runtime.training import write_json_atomic


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("eval_dir"), ap.add_argument("prefix"), ap.add_argument("trim", type=float)
    ap.add_argument("workdirs", nargs="+")
    ap.add_argument("--pairs", default="intra,inter")
    ap.add_argument("--seeds", default=None, help="labels of the workdirs (default 0, 1, ...)")
    ap.add_argument("--validity", action="store_true")
    ap.add_argument("--methods", default="soft,hard,adain,avatarnet,autoencoder")
    ap.add_argument("--world", action="store_true", help="then the first workdir under the world protocol too "
                    "(OUT_PREFIX_<pairs>_world_s<k>.json)")
    args = ap.parse_args(argv[1:])
    methods = tuple(args.methods.split(","))
    labels = args.seeds.split(",") if args.seeds else [str(i) for i in range(len(args.workdirs))]
    for pairs in args.pairs.split(","):
        for i, (label, wd) in enumerate(zip(labels, args.workdirs)):
            rep = evaluate(wd, args.eval_dir, pairs=pairs, methods=methods,
                           trim_seconds=args.trim, progress=False)
            if args.validity and i == 0 and pairs == "intra":
                rep["metric_validity"] = metric_validity(args.eval_dir, pairs="inter", trim_seconds=args.trim,
                                                         progress=False)
            write_json_atomic(f"{args.prefix}_{pairs}_s{label}.json", rep)
            print(pairs, label, rep["timing"], flush=True)
    if args.world:
        for pairs in args.pairs.split(","):
            rep = evaluate(args.workdirs[0], args.eval_dir, pairs=pairs, protocol="world",
                           methods=methods, progress=False)
            write_json_atomic(f"{args.prefix}_{pairs}_world_s{labels[0]}.json", rep)
            print(pairs, "world", labels[0], rep["timing"], flush=True)


if __name__ == "__main__":
    main(sys.argv)

"""Evaluate one trained run of this experiment on the test takes (006-008) and write a stamped results file.

    python experiments/tgst_bandai2/evaluate.py experiments/tgst_bandai2/runs/full_s0.toml [--data DIR]
    python experiments/tgst_bandai2/evaluate.py --table1 [--data DIR]     # data only: Table 1, cross form

Model runs: pairs of :func:`jaxgest.tgst.multitake.make_multitake_pairs` (one exemplar take per content
clip x style x exemplar gesture, rotating; zero-shot runs: only the held-out content), every method with
both input variants, the controls (:func:`jaxgest.tgst.multitake.evaluate_pairs`; the hands oracle on every
4th pair) and the round-trip arm speeds of every test clip. To fit the shared CPU, only seed 0 of the full
runs evaluates the "as is" input, the model-free controls and the oracle; the other runs evaluate the
pre-registered headline input (exemplar + mirror), the round trip and PCA-16
-> ``results/eval_NAME.json``. ``--table1``: :func:`jaxgest.tgst.multitake.cross_validity` and the
take-to-take spread of arm speed -> ``results/table1.json``. Numbers are rounded to 5 significant digits.
"""
import argparse
import tomllib
import pathlib
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parents[1] / ".." / "shared" / "data" / "bandai-namco-2"
EXEMPLAR_TAKES = 1
#: the paper's four methods and the registered lever (``coherent``: not in the paper)
METHODS = ("soft", "hard", "adain", "avatarnet", "coherent")


def _round(x):
    """Floats to 5 significant digits, clip paths to their file names (results files stay small)."""
    if isinstance(x, float):
        return float(f"{x:.5g}")
    if isinstance(x, str) and x.endswith(".bvh"):
        return pathlib.Path(x).name
    if isinstance(x, dict):
        return {k: _round(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_round(v) for v in x]
    return x


def main() -> int:
    from jaxgest.runtime.errors import DataError
    from jaxgest.motion import datasets
    from jaxgest.runtime.provenance import write_results
    from jaxgest.tgst import multitake as mt
    from jaxgest.tgst import multitake_eval as me

    ap = argparse.ArgumentParser()
    ap.add_argument("config", nargs="?")
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--table1", action="store_true")
    a = ap.parse_args()
    t0 = time.perf_counter()
    try:
        clips = datasets.load_folder(a.data)
        proto = me.multitake_protocol()
        if a.table1:
            test = mt.split_by_take(clips, mt.SPLITS["test"])
            speeds = [{"clip": str(c.path), "cell": f"{c.content}/{c.style}",
                       "speed": me.arm_speed(me.FeatureCache(proto, c.motion.fps)(c)[1])}
                      for c in mt.split_by_take(clips, [1, 2, 3, 4, 5, 6, 7, 8])]
            results = {"protocol": proto.describe(), "window": {"theta_at_60": 64},
                       "triples": me.cross_validity(clips, protocol=proto, progress=True), "arm_speeds": speeds,
                       "num_test_clips": len(test), "wall_s": time.perf_counter() - t0}
            write_results(HERE / "results" / "table1.json", _round(results), {"data": a.data, "takes": "006-008"})
            return 0
        from jaxgest.tgst.api import load_model

        cfg = tomllib.loads(pathlib.Path(a.config).read_text())
        model = load_model(HERE / "out" / "runs" / cfg["name"])
        held = cfg["hold_out_content"]
        pairs = mt.make_multitake_pairs(clips, exemplar_takes=EXEMPLAR_TAKES, contents=[held] if held else None)
        train = [c for c in mt.split_by_take(clips, cfg["train_takes"]) if c.content != held]
        pca = me.fit_pca(model, train)
        first = cfg["seed"] == 0 and not held and not cfg.get("extra_data")  # full_s0: variants, controls, oracle
        if not first and not held:  # seeds 1-2 of the full runs: the inter conditions only (CPU time)
            pairs = [p for p in pairs if p.condition != "intra"]
        report = me.evaluate_pairs(model, pairs, protocol=proto, pca=pca, progress=True, methods=METHODS,
                                   oracle_every=4 if first else 0, controls=first,
                                   variants=me.VARIANTS if first else ("mirror",))
        test = mt.split_by_take(clips, mt.SPLITS["test"])
        report["round_trip"] = me.round_trip_speeds(model, [c for c in test if not held or c.content == held], proto)
        report["exemplar_takes"] = EXEMPLAR_TAKES
        report["wall_s"] = time.perf_counter() - t0
    except DataError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    write_results(HERE / "results" / f"eval_{cfg['name']}.json", _round(report), cfg,
                  workdir=HERE / "out" / "runs" / cfg["name"])  # the stamp holds the training's code too
    print(f"{cfg['name']}: {len(pairs)} pairs in {report['wall_s']:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

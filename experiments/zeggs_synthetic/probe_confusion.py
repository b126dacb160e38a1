"""Where the style probe's gap to the raw statistics lives: per-style accuracy and confusions.

The pooled leave-one-content-out style probe of :mod:`jaxgest.zeggs.probes` (the folds, windows and ridge
classifier of ``jaxgest zeggs evaluate``) for two feature sets on the same windows: the trained encoder's
posterior mean (2 s windows) and the raw-statistics control (window mean + std of the normalised pose
features). Per style: the mean per-clip accuracy of each, their paired difference (SE over that style's
clips), and the style each one most often mistakes it for.

Usage (from experiments/zeggs_synthetic/):
    python probe_confusion.py --workdir out/RUN --data out/probe_data/seed{1..16} --json out/probe_confusion_RUN.json
    python probe_confusion.py --table out RUN [RUN ...]   # the gap's decomposition over runs, from those JSONs

Every style has the same number of clips (96 of 672), so the probe's gap to the raw statistics is the mean of
the per-style gaps: a style's share of it is its gap / 7. ``--table`` splits it into the handedness pair
(``neutral`` and ``left_handed``, which differ only by the hand of one-handed strokes), ``relaxed`` and the
other four styles, per run and as mean ± SE over the runs given.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np


def confusion_table(preds, labels, styles) -> np.ndarray:
    """Row = true style, column = predicted style, window counts."""
    idx = {s: k for k, s in enumerate(styles)}
    c = np.zeros((len(styles), len(styles)), int)
    for p, y in zip(preds, labels):
        for q in p:
            c[idx[y], idx[q]] += 1
    return c


PARTS = {"handedness pair (neutral, left_handed)": ("neutral", "left_handed"), "relaxed": ("relaxed",),
         "the other four": ("energetic", "proud", "sad", "tense")}


def table(out: pathlib.Path, runs) -> int:
    """Print each run's probe gap to the raw statistics split into :data:`PARTS` (and mean ± SE over runs)."""
    rows = []
    for r in runs:
        f = out / f"probe_confusion_{r}.json"
        if not f.is_file():
            sys.exit(f"probe_confusion: {f} not found; measure the run first (--workdir out/{r} ... --json {f})")
        st = json.loads(f.read_text())["styles"]
        total = sum(v["clips"] for v in st.values())
        row = {name: sum(st[s]["difference"] * st[s]["clips"] / total for s in part) for name, part in PARTS.items()}
        row["gap"] = sum(row.values())
        row["pair accuracy: embedding / raw"] = (np.mean([st[s]["embedding"] for s in PARTS[next(iter(PARTS))]]),
                                                 np.mean([st[s]["raw_statistics"] for s in PARTS[next(iter(PARTS))]]))
        rows.append(row)
    names = list(PARTS) + ["gap"]
    print("| run | " + " | ".join(f"share of the gap: {n}" if n != "gap" else "probe − raw statistics" for n in names)
          + " | handedness pair accuracy: embedding / raw |\n|---|" + "---:|" * (len(names) + 1))
    for r, row in zip(runs, rows):
        e, w = row["pair accuracy: embedding / raw"]
        print(f"| {r} | " + " | ".join(f"{row[n]:+.4f}" for n in names) + f" | {e:.3f} / {w:.3f} |")
    if len(rows) > 1:
        cells = []
        for n in names:
            v = np.array([row[n] for row in rows])
            cells.append(f"{v.mean():+.4f} ± {v.std(ddof=1) / np.sqrt(len(v)):.4f}")
        print(f"| mean ± SE over {len(rows)} runs | " + " | ".join(cells) + " | |")
    return 0


def main(argv=None) -> int:
    from tqdm.auto import tqdm

    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import probes
    from jaxgest.zeggs.inference import load_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", nargs="+", metavar=("OUT", "RUN"), help="decompose the gap of runs already measured")
    ap.add_argument("--workdir")
    ap.add_argument("--data", nargs="+", help="dataset folders, pooled")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    if args.table:
        return table(pathlib.Path(args.table[0]), args.table[1:])
    if not (args.workdir and args.data and args.json):
        ap.error("--workdir, --data and --json are required (or --table OUT RUN ...)")

    model = load_model(args.workdir)
    clips = [c for d in args.data for c in load_folder(d)]
    labels, contents = [c.style for c in clips], [c.content for c in clips]
    styles = sorted(set(labels))
    xs = [probes._windows(model, c, probes.PROBE_WINDOW_S, probes.PROBE_STRIDE_S)  # the probe's own windows
          for c in tqdm(clips, desc="windows", leave=False)]
    mus = [np.asarray(m, np.float64) for m in probes.encode_windows(model, xs)]
    raws = [np.concatenate([x.mean(1), x.std(1)], axis=1) for x in xs]
    out = {"workdir": str(args.workdir), "clips": len(clips), "window_s": probes.PROBE_WINDOW_S, "styles": {}}
    per = {}
    for name, feats in (("embedding", mus), ("raw_statistics", raws)):
        preds = probes.fold_predictions(feats, labels, contents)
        per[name] = np.array([np.mean([q == y for q in p]) for p, y in zip(preds, labels)])
        out[f"confusion_{name}"] = {"styles": styles, "counts": confusion_table(preds, labels, styles).tolist()}
    print(f"{args.workdir}: {len(clips)} clips; style probe embedding {per['embedding'].mean():.3f}, "
          f"raw statistics {per['raw_statistics'].mean():.3f}\n")
    print("| style | clips | embedding | raw statistics | embedding − raw (± SE) | embedding mistakes it for | "
          "raw statistics mistake it for |\n|---|---:|---:|---:|---:|---|---|")
    for k, s in enumerate(styles):
        rows = np.array([y == s for y in labels])
        d = per["embedding"][rows] - per["raw_statistics"][rows]
        se = float(d.std(ddof=1) / np.sqrt(rows.sum()))
        top = {}
        for name in per:
            c = np.array(out[f"confusion_{name}"]["counts"][k], float)
            c[k] = 0
            j = int(np.argmax(c))
            top[name] = f"{styles[j]} ({c[j] / np.sum(out[f'confusion_{name}']['counts'][k]):.3f})" if c[j] else "—"
        out["styles"][s] = {"clips": int(rows.sum()), "embedding": float(per["embedding"][rows].mean()),
                            "raw_statistics": float(per["raw_statistics"][rows].mean()),
                            "difference": float(d.mean()), "standard_error": se, "top_confusion": top}
        print(f"| {s} | {rows.sum()} | {per['embedding'][rows].mean():.3f} | {per['raw_statistics'][rows].mean():.3f} | "
              f"{d.mean():+.3f} ± {se:.3f} | {top['embedding']} | {top['raw_statistics']} |")
    # Which cue separates relaxed from neutral: a two-class probe (same folds) on the embedding, the raw
    # window means (static pose: lean, hand height) and the raw window stds (motion: amplitude, sway, tempo).
    pair = [i for i, y in enumerate(labels) if y in ("neutral", "relaxed")]
    p = xs[0].shape[2]
    out["relaxed_vs_neutral"] = {}
    print("\nrelaxed vs neutral, two-class probe (per-clip accuracy ± SE):", end="")
    for name, feats in (("embedding", mus), ("raw_statistics", raws), ("raw_means", [r[:, :p] for r in raws]),
                        ("raw_stds", [r[:, p:] for r in raws])):
        r = probes.grouped_probe([feats[i] for i in pair], [labels[i] for i in pair], [contents[i] for i in pair])
        out["relaxed_vs_neutral"][name] = r["clip_mean"]
        print(f" {name} {r['clip_mean']['mean']:.3f} ± {r['clip_mean']['standard_error']:.3f};", end="")
    print()
    pathlib.Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Ground-truth columns under both protocols, seed 0: markdown from the evaluation JSON files.

    python experiments/tgst_bandai/gt_table.py RESULTS_DIR [SEED] [PREFIX]

Reads PREFIX_{intra,inter}_s<SEED>.json (authors' protocol) and PREFIX_{intra,inter}_world_s<SEED>.json (world
protocol; PREFIX default ``eval``, e.g. ``eval_fitpca``); per method and control the mean over pairs of the
per-pair mean content / style errors against the content and style clips and against the ground truth (the
dataset clip of the content in the target style; intra: the style clip itself).
"""
import json
import pathlib
import sys

ROWS = (("adain", "AdaIN"), ("avatarnet", "Avatar-net"), ("hard", "Hard swap"), ("soft", "Soft swap (ours)"),
        ("autoencoder", "*autoencoder round trip*"), ("content_as_is", "*content as is*"),
        ("style_as_is", "*style as is*"))


def cells(report, name):
    src = report["controls"] if name in report.get("controls", {}) else report["methods"]
    e = src.get(name)
    if not e or "content" not in e:
        return ["-"] * 4
    return [f"{e[k]['mean']:.3f}" if e.get(k) else "-" for k in ("content", "style", "gt_content", "gt_style")]


def main(argv):
    folder, seed = pathlib.Path(argv[1]), (argv[2] if len(argv) > 2 else "0")
    prefix = argv[3] if len(argv) > 3 else "eval"
    for label, tag in (("authors (0.3 s cut)", ""), ("world", "_world")):
        files = [folder / f"{prefix}_{p}{tag}_s{seed}.json" for p in ("intra", "inter")]
        if not all(f.exists() for f in files):
            continue
        intra, inter = (json.loads(f.read_text()) for f in files)
        print(f"**{label}, seed {seed}** (mean over pairs of the per-pair means; GT = the dataset clip of the "
              "content in the target style; intra GT = the style clip)\n")
        print("| Method | intra content | intra style | intra GT content | intra GT style | inter content | "
              "inter style | inter GT content | inter GT style |")
        print("|" + "---|" * 9)
        for name, text in ROWS:
            print(f"| {text} | " + " | ".join(cells(intra, name) + cells(inter, name)) + " |")
        print()


if __name__ == "__main__":
    main(sys.argv)

"""Markdown tables of the TGST Bandai-Namco experiment from its JSON results (paper 000 Tables 1-4).

    python experiments/tgst_bandai/make_tables.py experiments/tgst_bandai/out/results > tables.md

Reads, from the results folder, whichever of these exist: eval_intra.json (Table 2 + its metric_validity =
Table 1), eval_inter.json (Table 3), eval_ablate_<term>.json (Table 4, soft swap on intra pairs; the "full"
row is the soft row of eval_intra.json), validity_full.json (Table 1 on the whole dataset),
eval_identity_{intra,inter}.json (no-transfer reference rows), diagnose.json (autoencoder round trips),
ext_ae12k_{eval_intra,diagnose}.json (the run with twice the autoencoder steps),
timings.tsv and train_*.txt. Missing files give a note instead of a table, so partial runs still tabulate.
Units: content errors in metres (DTW over both hands' positions), style errors in m/s (arm velocity
statistics); see jaxgest/tgst/evaluate.py.
"""

from __future__ import annotations

import json
import pathlib
import sys

STATS = ("mean", "worst", "w25")
LABELS = {"soft": "Soft swap (ours)", "hard": "Hard swap", "adain": "AdaIN", "avatarnet": "Avatar-net"}
TERMS = ("identity", "cyclic", "structure", "appearance")


def _load(folder: pathlib.Path, name: str):
    p = folder / name
    return json.loads(p.read_text()) if p.is_file() else None


def _cells(stats, digits=3):
    return ["-"] * len(STATS) if stats is None else [f"{stats[k]:.{digits}f}" for k in STATS]


def _row(cells):
    return "| " + " | ".join(cells) + " |"


def _header(first, groups):
    head = [first] + [f"{g} {k}" for g in groups for k in STATS]
    return [_row(head), "|" + "---|" * len(head)]


def _best(values, lower=True):
    """Index of the best value (ties -> first)."""
    return min(range(len(values)), key=lambda i: values[i]) if lower else max(range(len(values)), key=lambda i: values[i])


def validity_table(v, title):
    lines = [f"**{title}** ({v['pairs']} pairs of {v['data']}, {v['num_pairs']} with a ground truth distinct "
             "from the style clip). Each sample is scored against the ground truth (the content performed in "
             "the target style); a valid metric ranks the content sample first on the content error and the "
             "style sample first on the style error.", ""]
    lines += _header("Sample vs ground truth", ("content error (m)", "style error (m/s)"))
    for row in ("content", "style"):
        cols = v["rows"][row]
        lines.append(_row([f"{row} sample"] + _cells(cols["content"]) + _cells(cols["style"])))
    c, s = v["rows"]["content"], v["rows"]["style"]
    ok_c = c["content"]["mean"] < s["content"]["mean"]
    ok_s = s["style"]["mean"] < c["style"]["mean"]
    lines += ["", f"Content metric valid (content sample < style sample, mean): **{'yes' if ok_c else 'no'}**; "
              f"style metric valid (style sample < content sample, mean): **{'yes' if ok_s else 'no'}**."]
    return "\n".join(lines)


def methods_table(report, title, identity=None):
    n = report["num_pairs"]
    m0 = next(iter(report["methods"].values()))
    lines = [f"**{title}**: {n} pairs ({m0['num_evaluated']} evaluated, {m0['num_skipped']} skipped: clip shorter "
             f"than one style window), {report['pairs']}-scenario, held-out contents only. Lower is better; "
             "best of each column in bold.", ""]
    groups = ("content", "style", "gt_content", "gt_style")
    names = {"content": "content (m)", "style": "style (m/s)", "gt_content": "GT content (m)",
             "gt_style": "GT style (m/s)"}
    lines += _header("Method", [names[g] for g in groups])
    methods = list(report["methods"])
    best = {(g, k): _best([report["methods"][m][g][k] if report["methods"][m][g] else float("inf")
                           for m in methods]) for g in groups for k in STATS}
    for i, m in enumerate(methods):
        cells = [LABELS.get(m, m)]
        for g in groups:
            s = report["methods"][m][g]
            for k, c in zip(STATS, _cells(s)):
                cells.append(f"**{c}**" if s is not None and best[(g, k)] == i else c)
        lines.append(_row(cells))
    if identity is not None:
        s = identity["methods"]["soft"]
        lines.append(_row(["*no transfer (content clip returned)*"] + [
            f"*{c}*" for g in groups for c in _cells(s[g])]))
        lines += ["", "The last row is a reference, not a method: the content clip scored as if it were the result "
                  "(baseline_identity.py); it is not counted for the bold minima."]
    return "\n".join(lines)


def diagnose_table(d):
    m = d["mean"]
    lines = [f"**Autoencoder round trips** ({d['num_clips']} held-out clips, each scored against itself; "
             "diagnose.py). Arm speed = mean speed of the 8 arm joints.", "",
             "| variant | content error (m) | style error (m/s) | arm speed (m/s) |", "|---|---|---|---|",
             f"| original clip | 0 | 0 | {m['clip']['speed']:.3f} |"]
    names = {"roundtrip": "body conversion + floor placement, no network",
             "ae_upper": "AE upper body, original lower body", "ae_full": "AE upper and lower body"}
    for k, label in names.items():
        lines.append(f"| {label} | {m[k]['content']:.3f} | {m[k]['style']:.3f} | {m[k]['speed']:.3f} |")
    a = d.get("ae_angle_deg")
    if a:
        lines += ["", "Autoencoder mean angular reconstruction error (upper body, 60 fps): "
                  + ", ".join(f"{k.replace('_', '-')} clips {v:.2f}°" for k, v in a.items()) + "."]
    sw = d.get("soft_swap")
    if sw:
        lines += ["", f"Soft swap sharpness ({sw['num_pairs']} intra pairs): mean largest swap weight "
                  f"{sw['max_weight']:.3f}, mean effective number of blended style tokens "
                  f"{sw['effective_tokens']:.3f} (1 = hard swap)."]
    return "\n".join(lines)


def extension_table(folder, intra, diag):
    """Main run vs the extension with twice the autoencoder steps (ext_ae12k_*), intra pairs, mean errors."""
    ext, ext_diag = _load(folder, "ext_ae12k_eval_intra.json"), _load(folder, "ext_ae12k_diagnose.json")
    if ext is None or ext_diag is None or intra is None or diag is None:
        return ""
    lines = ["**Extension: 12,000 autoencoder steps instead of 6,000** (same seed; transformer retrained 10,000 "
             "steps on it; intra pairs; mean errors).", "",
             "| AE steps | AE angle, held-out clips (°) | AE round-trip style error (m/s) | "
             + " | ".join(f"{LABELS[m]} content / style" for m in intra["methods"]) + " |",
             "|---|---|---|" + "---|" * len(intra["methods"])]
    for steps, r, d in ((6000, intra, diag), (12000, ext, ext_diag)):
        cells = [str(steps), f"{d['ae_angle_deg']['held_out']:.2f}", f"{d['mean']['ae_full']['style']:.2f}"]
        cells += [f"{r['methods'][m]['content']['mean']:.3f} / {r['methods'][m]['style']['mean']:.2f}"
                  for m in intra["methods"]]
        lines.append(_row(cells))
    return "\n".join(lines)


def ablation_table(folder, intra):
    rows = []
    if intra is not None and "soft" in intra["methods"]:
        rows.append(("full (all four terms)", intra["methods"]["soft"], intra["num_pairs"]))
    missing = []
    for t in TERMS:
        r = _load(folder, f"eval_ablate_{t}.json")
        if r is None:
            missing.append(t)
            continue
        rows.append((f"w/o L_{t}", r["methods"]["soft"], r["num_pairs"]))
    if not rows:
        return "**Table 4**: no ablation results yet."
    lines = ["**Table 4 analogue** (soft swap, intra-scenario pairs of the held-out contents; each row retrains "
             "the transformer with one loss term off on the same autoencoder, same seed and steps).", ""]
    lines += _header("Loss", ("content (m)", "style (m/s)"))
    for name, s, _ in rows:
        lines.append(_row([name] + _cells(s["content"]) + _cells(s["style"])))
    if missing:
        lines += ["", f"Missing (not run): {', '.join('w/o L_' + t for t in missing)}."]
    return "\n".join(lines)


def timings(folder):
    p = folder / "timings.tsv"
    if not p.is_file():
        return ""
    rows = [line.split("\t") for line in p.read_text().splitlines()[1:] if line.strip()]
    lines = ["**Wall times** (2 shared CPU cores, nice 5)", "", "| stage | start (UTC) | wall (s) |", "|---|---|---|"]
    lines += [f"| {r[0]} | {r[1]} | {r[2]} |" for r in rows]
    total = sum(int(r[2]) for r in rows)
    lines.append(f"| **total** | | **{total}** ({total / 60:.1f} min) |")
    return "\n".join(lines)


def training(folder):
    lines = []
    for p in sorted(folder.glob("train_*.txt")):
        text = [line for line in p.read_text().splitlines() if line.startswith("tgst train")]
        if text:
            lines.append(f"* `{p.stem}`: {text[-1]}")
    return "**Training summaries** (last line of `jaxgest tgst train`)\n\n" + "\n".join(lines) if lines else ""


def main(argv) -> int:
    if len(argv) != 2:
        print("usage: make_tables.py RESULTS_DIR", file=sys.stderr)
        return 2
    folder = pathlib.Path(argv[1])
    if not folder.is_dir():
        print(f"make_tables.py: {folder}: no such folder", file=sys.stderr)
        return 2
    intra, inter = _load(folder, "eval_intra.json"), _load(folder, "eval_inter.json")
    full = _load(folder, "validity_full.json")
    parts = []
    if intra is not None and "metric_validity" in intra:
        parts.append(validity_table(intra["metric_validity"], "Table 1 analogue, held-out contents"))
    if full is not None:
        parts.append(validity_table(full, "Table 1 analogue, whole dataset"))
    id_intra, id_inter = _load(folder, "eval_identity_intra.json"), _load(folder, "eval_identity_inter.json")
    parts.append(methods_table(intra, "Table 2 analogue (intra-scenario)", id_intra) if intra
                 else "**Table 2**: not run yet.")
    parts.append(methods_table(inter, "Table 3 analogue (inter-scenario)", id_inter) if inter
                 else "**Table 3**: not run yet.")
    diag = _load(folder, "diagnose.json")
    if diag is not None:
        parts.append(diagnose_table(diag))
    parts.append(ablation_table(folder, intra))
    ext = extension_table(folder, intra, diag)
    if ext:
        parts.append(ext)
    for extra in (training(folder), timings(folder)):
        if extra:
            parts.append(extra)
    print("\n\n".join(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

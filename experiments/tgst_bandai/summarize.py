"""Tables 2/3 (and 4) over seeds from `jaxgest tgst evaluate` JSON files, with controls and paired differences.

    python experiments/tgst_bandai/summarize.py TITLE PAPER_TABLE EVAL_SEED0.json [EVAL_SEED1.json ...]

PAPER_TABLE: 2 (intra), 3 (inter) or 0 (none). For every method and control: each statistic (mean / worst /
w25 of the content and style errors) averaged over the evaluated pairs, then over the seeds (+- the
standard deviation over seeds when there are several); the paper's numbers beside ours; then paired
differences "soft swap minus X" of the per-pair mean errors (averaged over seeds per pair), with their
standard error over pairs and the number of pairs where soft swap is lower; then the swap diagnostics.
Prints markdown.
"""

from __future__ import annotations

import json
import sys

import numpy as np

STATS = ("mean", "worst", "w25")
LABELS = {"soft": "Soft swap (ours)", "hard": "Hard swap", "adain": "AdaIN", "avatarnet": "Avatar-net",
          "autoencoder": "*autoencoder round trip (no style)*", "content_as_is": "*content as is*",
          "style_as_is": "*style as is*"}
PAPER = {  # Kuriyama et al. 2022, Tables 2 and 3: content mean/worst/w25, style mean/worst/w25
    2: {"adain": (0.192, 0.421, 0.289, 0.763, 1.59, 1.34), "avatarnet": (0.189, 0.491, 0.334, 0.92, 2.07, 1.61),
        "hard": (0.171, 0.493, 0.307, 0.886, 2.07, 1.64), "soft": (0.16, 0.443, 0.289, 0.646, 1.43, 1.19)},
    3: {"adain": (0.239, 0.49, 0.35, 0.782, 1.68, 1.39), "avatarnet": (0.258, 0.626, 0.439, 1.01, 2.13, 1.75),
        "hard": (0.212, 0.528, 0.359, 0.959, 2.02, 1.7), "soft": (0.206, 0.495, 0.348, 0.693, 1.49, 1.27)},
}


def per_pair(report, name):
    """{pair key: {"content": stats, "style": stats}} of one method or control."""
    out = {}
    for r in report["per_pair"]:
        src = r.get("controls", {}) if name in ("content_as_is", "style_as_is") else r.get("errors", {})
        e = src.get(name)
        if e and "skipped" not in e:
            out[(r["content"], r["style"])] = e
    return out


def main(argv) -> int:
    title, paper_table, files = argv[1], int(argv[2]), argv[3:]
    reports = [json.loads(open(f).read()) for f in files]
    methods = [m for m in ("adain", "avatarnet", "hard", "soft", "autoencoder") if m in reports[0]["methods"]]
    rows = methods + ["content_as_is", "style_as_is"]
    data = {name: [per_pair(r, name) for r in reports] for name in rows}
    n_seeds = len(reports)
    print(f"**{title}** ({reports[0]['pairs']} pairs, protocol {reports[0].get('protocol', {}).get('name', '?')}, "
          f"{n_seeds} seed(s); pairs evaluated: {len(data['soft'][0]) if 'soft' in data else '?'}). "
          "Each cell: average over pairs, then over seeds" + (" (+- std over seeds)" if n_seeds > 1 else "")
          + "; paper values in brackets.\n")
    head = ["Method"] + [f"{g} {s}" for g in ("content (m)", "style (m/s)") for s in STATS]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for name in rows:
        cells = [LABELS[name]]
        paper = PAPER.get(paper_table, {}).get(name)
        for gi, g in enumerate(("content", "style")):
            for si, s in enumerate(STATS):
                per_seed = [np.mean([e[g][s] for e in d.values()]) for d in data[name] if d]
                if not per_seed:
                    cells.append("-")
                    continue
                cell = f"{np.mean(per_seed):.3f}"
                if n_seeds > 1 and name not in ("content_as_is", "style_as_is"):
                    cell += f" +- {np.std(per_seed):.3f}"
                if paper is not None:
                    cell += f" [{paper[gi * 3 + si]}]"
                cells.append(cell)
        print("| " + " | ".join(cells) + " |")
    if "soft" in data:
        print("\nPaired differences of the per-pair mean errors, soft swap minus X (per pair averaged over the "
              "seeds; mean +- standard error over pairs; 'soft lower' = pairs where soft swap is lower):\n")
        print("| X | content diff (m) | soft lower | style diff (m/s) | soft lower | pairs |")
        print("|---|---|---|---|---|---|")
        keys = set.intersection(*[set(d) for d in data["soft"]])
        for name in rows:
            if name == "soft":
                continue
            k2 = [k for k in keys if all(k in d for d in data[name])]
            if not k2:
                continue
            cells = [LABELS[name]]
            for g in ("content", "style"):
                diff = np.array([np.mean([ds[k][g]["mean"] - dx[k][g]["mean"]
                                          for ds, dx in zip(data["soft"], data[name])]) for k in k2])
                se = diff.std(ddof=1) / np.sqrt(len(diff)) if len(diff) > 1 else float("nan")
                cells += [f"{diff.mean():+.3f} +- {se:.3f}", f"{int((diff < 0).sum())}/{len(diff)}"]
            cells.append(str(len(k2)))
            print("| " + " | ".join(cells) + " |")
    sw = [r.get("swap_diagnostics") for r in reports if r.get("swap_diagnostics")]
    if sw:
        keys = ("max_weight", "effective_tokens", "argmax_within_1", "chance_within_1")
        print("\nSoft-swap diagnostics (mean over pairs" + (", per seed" if n_seeds > 1 else "") + "): "
              + "; ".join(", ".join(f"{k} {s[k]:.3f}" for k in keys if k in s) for s in sw) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

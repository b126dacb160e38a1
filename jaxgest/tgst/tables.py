"""Markdown tables of TGST evaluation reports (:func:`jaxgest.tgst.evaluate.evaluate`): the paper's Tables
1-3 layout with ground-truth columns, control rows and the protocol of every row, and the swap diagnostics.
References: Kuriyama et al. 2022, Tables 1-3.
"""

from __future__ import annotations

STATS = ("mean", "worst", "w25")
ERROR_KEYS = ("content", "style", "gt_content", "gt_style")


_LABELS = {
    "soft": "Soft swap (ours)",
    "hard": "Hard swap (19)",
    "adain": "AdaIN (17)",
    "avatarnet": "Avatar-net (18)",
    "autoencoder": "Autoencoder round trip",
    "content_as_is": "Content as is (control)",
    "style_as_is": "Style as is (control)",
}


def _fmt(stats: dict | None) -> list[str]:
    return ["-"] * 3 if stats is None else [f"{stats[k]:.3g}" for k in STATS]


def markdown_table(report: dict) -> str:
    """The paper's Table 2/3 layout (+ ground-truth columns, + control rows) as markdown, one row per method,
    with the protocol of every row."""
    head = [
        "Method",
        "protocol",
        "n",
        *(f"content {k}" for k in STATS),
        *(f"style {k}" for k in STATS),
        *(f"gt content {k}" for k in STATS),
        *(f"gt style {k}" for k in STATS),
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    rows = list(report["methods"].items()) + list((report.get("controls") or {}).items())
    for m, s in rows:
        proto = s.get("protocol", report.get("protocol", {}).get("name", "-"))
        cells = [_LABELS.get(m, m), proto, str(s.get("num_evaluated", "-"))]
        cells += [c for k in ERROR_KEYS for c in _fmt(s[k])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def diagnostics_table(report: dict) -> str:
    """Swap diagnostics of a report as one markdown row ('' when the report has none)."""
    d = report.get("swap_diagnostics")
    if not d:
        return ""
    head = ["soft swap", "pairs", "mean max weight", "effective tokens", "argmax within +-1", "chance",
            "padding mass"]
    cells = ["weights (eq. 4)", str(d["num_pairs"]), f"{d['max_weight']:.3g}", f"{d['effective_tokens']:.3g}",
             f"{d['argmax_within_1']:.3g}", f"{d['chance_within_1']:.3g}", f"{d['padding_mass']:.3g}"]
    return "\n".join(["| " + " | ".join(head) + " |", "|" + "---|" * len(head), "| " + " | ".join(cells) + " |"])


def validity_table(table: dict) -> str:
    """The paper's Table 1 layout as markdown: rows content / style sample, content and style errors."""
    head = ["Samples", "protocol", *(f"content {k}" for k in STATS), *(f"style {k}" for k in STATS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row, cols in table["rows"].items():
        cells = [row.capitalize(), table.get("protocol", "-")] + [c for k in ("content", "style") for c in _fmt(cols[k])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)

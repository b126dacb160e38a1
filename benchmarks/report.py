"""Markdown table, side-by-side ratios, and the per-pose-cost-vs-length plot."""

from __future__ import annotations

import pathlib
from collections import defaultdict


def ratios(records: list[dict]) -> dict:
    """``{case: {impl: median / median of jit}}`` for cases timed with several impls in the same run."""
    by_case = defaultdict(dict)
    for r in records:
        by_case[r["case"]][r["impl"]] = r["median_us"]
    out = {}
    for case, impls in by_case.items():
        if "jit" in impls and len(impls) > 1:
            out[case] = {k: v / impls["jit"] for k, v in impls.items() if k != "jit"}
    return out


def markdown_table(records: list[dict]) -> str:
    rat = ratios(records)
    lines = [
        "| case | impl | batch | frames | per-pose µs | median ms | min ms | compile s | vs jit |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in records:
        comp = "" if r.get("compile_s") is None else f"{r['compile_s']:.2f}"
        vs = rat.get(r["case"], {}).get(r["impl"])
        lines.append(
            f"| {r['case']} | {r['impl']} | {r['batch']} | {r['frames']} | {r['per_pose_us']:.4g} | "
            f"{r['median_us'] / 1e3:.4g} | {r['min_us'] / 1e3:.4g} | {comp} | {'' if vs is None else f'{vs:.1f}x'} |"
        )
    return "\n".join(lines)


def plot_scaling(records: list[dict], out_png, group: str = "tgst_scaling") -> pathlib.Path | None:
    """Per-pose cost against clip length for the records of ``group`` (PNG, matplotlib Agg)."""
    rows = sorted((r for r in records if r.get("group") == group), key=lambda r: r["frames"])
    if not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxgest.io import atomic_output

    fig, ax = plt.subplots(figsize=(5.5, 3.4), dpi=110)
    xs = [r["frames"] for r in rows]
    ax.plot(xs, [r["per_pose_us"] for r in rows], "o-", label="median")
    ax.plot(xs, [r["min_us"] / r["poses"] for r in rows], ".--", alpha=0.6, label="min")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("content clip length (frames), style clip 1280 frames")
    ax.set_ylabel("µs per pose (batch 1, jit)")
    ax.set_ylim(bottom=0)
    ax.set_title("TGST transfer: per-pose cost vs clip length")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_output(out_png) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return pathlib.Path(out_png)

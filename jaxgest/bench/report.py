"""Markdown tables (every record; eager/jit and numpy/jit side by side; compile times), scaling plot."""

from __future__ import annotations

import pathlib
from collections import defaultdict


def ratios(records: list[dict]) -> dict:
    """``{case: {impl: median / median of jit}}`` for cases timed with jit and other impls in one run."""
    by_case: dict = defaultdict(dict)
    for r in records:
        by_case[r["case"]][r["impl"]] = r["median_us"]
    out = {}
    for case, impls in by_case.items():
        if "jit" in impls and len(impls) > 1:
            out[case] = {k: v / impls["jit"] for k, v in impls.items() if k != "jit"}
    return out


def _is_torch(impl: str) -> bool:
    """An eager PyTorch peer (``torch``, ``torch_1t``); compiled peers are :func:`_is_torch_compiled`."""
    return (impl == "torch" or impl.startswith("torch_")) and not _is_torch_compiled(impl)


def _is_torch_compiled(impl: str) -> bool:
    return impl.startswith("torch_compile")


def peer_compile_ratios(records: list[dict]) -> dict:
    """``{case: {"jit_ms", "eager_ms", "compiled_ms", "jit_vs_eager", "jit_vs_compiled", "compile_s", ...}}``
    for cases with a jit impl and PyTorch peers: best eager (any thread setting) and best compiled median;
    ratios > 1 mean jit is faster. ``*_floor``: the fraction of the machine's floor each reached."""
    by_case: dict = defaultdict(dict)
    for r in records:
        by_case[r["case"]][r["impl"]] = r
    out = {}
    for case, impls in by_case.items():
        if "jit" not in impls:
            continue
        eager = [r for k, r in impls.items() if _is_torch(k)]
        comp = [r for k, r in impls.items() if _is_torch_compiled(k)]
        if not eager and not comp:
            continue
        jit = impls["jit"]
        row = {"jit_ms": jit["median_us"] / 1e3, "jit_compile_s": jit.get("compile_s"),
               "jit_floor": jit.get("floor_fraction")}
        for label, group in (("eager", eager), ("compiled", comp)):
            if group:
                best = min(group, key=lambda r: r["median_us"])
                row.update({f"{label}_ms": best["median_us"] / 1e3, f"{label}_impl": best["impl"],
                            f"jit_vs_{label}": best["median_us"] / jit["median_us"],
                            f"{label}_floor": best.get("floor_fraction")})
                if label == "compiled":
                    row["compile_s"] = best.get("compile_s")
        out[case] = row
    return out


def peer_compile_table(records: list[dict]) -> str:
    """jit vs the best eager and the best ``torch.compile`` peer per case: ms per call, speed-ups, compile
    seconds, fraction of the machine's floor."""
    rat = peer_compile_ratios(records)
    if not rat:
        return ""

    def f(x, fmt):
        return "" if x is None else format(x, fmt)

    def pct(x):
        return "" if x is None else f"{100 * x:.1f} %"

    lines = ["| case | jit ms | eager ms | compiled ms | jit vs eager | jit vs compiled | jit compile s | "
             "torch.compile s | jit of floor | eager of floor | compiled of floor |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for case, r in rat.items():
        lines.append(f"| {case} | {r['jit_ms']:.2f} | {f(r.get('eager_ms'), '.2f')} | {f(r.get('compiled_ms'), '.2f')} | "
                     f"{f(r.get('jit_vs_eager'), '.2f')}{'x' if 'jit_vs_eager' in r else ''} | "
                     f"{f(r.get('jit_vs_compiled'), '.2f')}{'x' if 'jit_vs_compiled' in r else ''} | "
                     f"{f(r.get('jit_compile_s'), '.1f')} | {f(r.get('compile_s'), '.1f')} | {pct(r.get('jit_floor'))} | "
                     f"{pct(r.get('eager_floor'))} | {pct(r.get('compiled_floor'))} |")
    return "\n".join(lines)


def peer_ratios(records: list[dict]) -> dict:
    """``{case: {impl: best torch median / impl median}}`` for cases with PyTorch peers (> 1: faster).

    "best torch" is the fastest of the case's eager ``torch*`` implementations (thread settings) in this
    run (``torch.compile`` peers: :func:`peer_compile_ratios`).
    """
    by_case: dict = defaultdict(dict)
    for r in records:
        by_case[r["case"]][r["impl"]] = r["median_us"]
    out = {}
    for case, impls in by_case.items():
        peers = [v for k, v in impls.items() if _is_torch(k)]
        if peers and len(peers) < len(impls):
            best = min(peers)
            out[case] = {k: best / v for k, v in impls.items() if not _is_torch(k) and not _is_torch_compiled(k)}
    return out


def peer_table(records: list[dict]) -> str:
    """Cases with a PyTorch peer: ms per call of each impl and the speed-up over torch."""
    rat = peer_ratios(records)
    if not rat:
        return ""
    lines = ["| case | batch | frames | impl | median ms | best torch ms | speed-up vs torch | floor | of floor |",
             "|---|---:|---:|---|---:|---:|---:|---|---:|"]
    torch_ms: dict = {}
    for r in records:
        if _is_torch(r["impl"]):
            torch_ms[r["case"]] = min(torch_ms.get(r["case"], float("inf")), r["median_us"] / 1e3)
    for r in records:
        if r["case"] in rat and not _is_torch(r["impl"]) and not _is_torch_compiled(r["impl"]):
            frac = r.get("floor_fraction")
            lines.append(f"| {r['case']} | {r['batch']} | {r['frames']} | {r['impl']} | {r['median_us'] / 1e3:.2f} | "
                         f"{torch_ms[r['case']]:.2f} | {rat[r['case']][r['impl']]:.2f}x | "
                         f"{r.get('floor_bound') or ''} | {'' if frac is None else f'{100 * frac:.0f} %'} |")
    return "\n".join(lines)


def floor_table(records: list[dict]) -> str:
    """Records with a work estimate: GFLOP/s, GB/s achieved and the fraction of the compute/memory floor."""
    rows = [r for r in records if r.get("floor_fraction") is not None]
    if not rows:
        return ""
    lines = ["| case | impl | GFLOP/s | GB/s | bound | of floor |", "|---|---|---:|---:|---|---:|"]
    for r in rows:
        s = r["median_us"] * 1e-6
        lines.append(f"| {r['case']} | {r['impl']} | {r['flops'] / s / 1e9:.1f} | {r['bytes'] / s / 1e9:.2f} | "
                     f"{r['floor_bound']} | {100 * r['floor_fraction']:.0f} % |")
    return "\n".join(lines)


def _us(x: float) -> str:
    return f"{x:,.1f}" if x < 1e4 else f"{x:,.0f}"


def markdown_table(records: list[dict]) -> str:
    """One row per record: per-pose, median and min µs, compile seconds, and the ratio to jit."""
    rat = ratios(records)
    lines = [
        "| case | impl | batch | frames | per-pose µs | median µs | min µs | compile s | repeats | vs jit |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in records:
        comp = "" if r.get("compile_s") is None else f"{r['compile_s']:.2f}"
        vs = rat.get(r["case"], {}).get(r["impl"])
        lines.append(
            f"| {r['case']} | {r['impl']} | {r['batch']} | {r['frames']} | {r['per_pose_us']:.4g} | "
            f"{_us(r['median_us'])} | {_us(r['min_us'])} | {comp} | {r['repeats']} | "
            f"{'' if vs is None else f'{vs:.2f}x'} |"
        )
    return "\n".join(lines)


def ratio_table(records: list[dict]) -> str:
    """Cases timed with jit and other impls: per-pose µs of each impl and ``<impl>/jit``, one row per case."""
    rows: dict = defaultdict(dict)
    meta = {}
    for r in records:
        rows[r["case"]][r["impl"]] = r
        meta.setdefault(r["case"], (r["batch"], r["frames"]))
    cases = [c for c, impls in rows.items() if "jit" in impls and len(impls) > 1]
    if not cases:
        return ""
    others = sorted({i for c in cases for i in rows[c] if i != "jit"}, key=lambda i: (i != "eager", i))
    head = ["case", "batch", "frames", "jit µs/pose"] + [f"{i} µs/pose" for i in others]
    head += [f"{i}/jit" for i in others]
    lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
    for c in cases:
        jit = rows[c]["jit"]["median_us"]
        cells = [c, str(meta[c][0]), str(meta[c][1]), f"{rows[c]['jit']['per_pose_us']:.4g}"]
        cells += [f"{rows[c][i]['per_pose_us']:.4g}" if i in rows[c] else "" for i in others]
        cells += [f"{rows[c][i]['median_us'] / jit:.2f}x" if i in rows[c] else "" for i in others]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def compile_table(records: list[dict]) -> str:
    """Jit records: trace, lower and compile seconds apart, and the steady-state per-frame latency."""
    rows = [r for r in records if r.get("compile_s") is not None]
    if not rows:
        return ""
    lines = ["| case | impl | trace s | lower s | compile s | per-frame µs |",
             "|---|---|---:|---:|---:|---:|"]
    for r in rows:
        cells = [f"{r[k]:.2f}" if r.get(k) is not None else "" for k in ("trace_s", "lower_s", "compile_s")]
        per_frame = r.get("per_frame_us", r["median_us"] / r["frames"])
        lines.append(f"| {r['case']} | {r['impl']} | " + " | ".join(cells) + f" | {per_frame:.4g} |")
    return "\n".join(lines)


def scaling_groups(records: list[dict]) -> list[str]:
    """Groups whose records span at least two clip lengths (the ones worth a scaling plot)."""
    frames: dict = defaultdict(set)
    for r in records:
        if r.get("group"):
            frames[r["group"]].add(r["frames"])
    return [g for g, f in frames.items() if len(f) >= 2]


def plot_scaling(records: list[dict], out_png, group: str | None = None) -> pathlib.Path | None:
    """Per-pose cost (median, min dashed) against clip length, one line per group and impl (PNG, Agg).

    ``group=None`` plots every group spanning several clip lengths. Returns the path, or None when there
    is nothing to plot.
    """
    groups = [group] if group else scaling_groups(records)
    series: dict = defaultdict(list)
    for r in records:
        if r.get("group") in groups:
            series[(r["group"], r["impl"])].append(r)
    series = {k: sorted(v, key=lambda r: r["frames"]) for k, v in series.items() if len(v) >= 2}
    if not series:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxgest.runtime.io import atomic_output

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    for (grp, impl), rows in sorted(series.items()):
        xs = [r["frames"] for r in rows]
        poses = [r.get("poses") or r["batch"] * r["frames"] for r in rows]
        line = ax.plot(xs, [r["per_pose_us"] for r in rows], "o-", label=f"{grp} / {impl} (median)")[0]
        ax.plot(xs, [r["min_us"] / p for r, p in zip(rows, poses)], ".--", alpha=0.5, color=line.get_color())
    batches = sorted({r["batch"] for rows in series.values() for r in rows})
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("clip length (frames)")
    ax.set_ylabel(f"µs per pose (batch {', '.join(map(str, batches))}; dashed: min)")
    ax.set_title("Per-pose cost against clip length")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_output(out_png) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return pathlib.Path(out_png)

"""``jaxgest plot W [W2 ...] --out curves.png``: training and held-out curves of training runs.

Reads each workdir's ``metrics.jsonl`` (:func:`jaxgest.bench.train_compare.read_metrics`) and draws one panel
per stage (a TGST run has ``autoencoder`` and ``transformer``, a ZeroEGGS run ``zeggs``): per workdir, the
logged training metric (solid; each point the mean over its log interval, docs/design.md §10) and, where the
run was trained with ``--eval-every``, the held-out one (``eval_<metric>``, dashed with markers) in the same
colour. Lines logged twice for one step (a run resumed from a checkpoint older than its last log line) keep
the later one.
"""

from __future__ import annotations

import pathlib
from typing import Optional, Sequence

from jaxgest.runtime.errors import DataError

#: the held-out metrics' prefix in metrics.jsonl (jaxgest.runtime.training.EVAL_PREFIX)
EVAL_PREFIX = "eval_"
PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def register(subparsers) -> None:
    p = subparsers.add_parser("plot", help="training and held-out loss curves of workdirs (metrics.jsonl)")
    p.add_argument("workdirs", nargs="+", metavar="W", help="training workdirs (each with a metrics.jsonl)")
    p.add_argument("--out", required=True, help="output image: .png, .svg or .pdf")
    p.add_argument("--metric", default="loss", help="the logged metric to draw (default loss; its held-out "
                   "curve is eval_<metric>)")
    p.add_argument("--labels", default=None,
                   help="comma-separated legend labels (default: the workdirs' names)")
    p.add_argument("--log-y", action="store_true", help="logarithmic y axis")
    p.set_defaults(func=_plot)


def curves(rows: Sequence[dict], metric: str) -> dict[str, dict[str, tuple[list, list]]]:
    """``{stage: {"train": (steps, values), "eval": (steps, values)}}`` of ``metric`` from metrics rows (stage
    ``""`` when the rows name none); a step logged twice keeps its later line."""
    by_stage: dict[str, dict[str, dict[int, float]]] = {}
    for r in rows:
        if "step" not in r:
            continue
        stage = by_stage.setdefault(str(r.get("stage", "")), {"train": {}, "eval": {}})
        for kind, key in (("train", metric), ("eval", EVAL_PREFIX + metric)):
            if isinstance(r.get(key), (int, float)):
                stage[kind][int(r["step"])] = float(r[key])
    out = {}
    for stage, kinds in by_stage.items():
        if kinds["train"] or kinds["eval"]:
            out[stage] = {kind: (sorted(v), [v[s] for s in sorted(v)]) for kind, v in kinds.items()}
    return out


def plot_training_curves(workdirs: Sequence, out, *, metric: str = "loss",
                         labels: Optional[Sequence[str]] = None, log_y: bool = False) -> pathlib.Path:
    """Draw ``metric`` (and ``eval_<metric>``) of every workdir into ``out`` (see the module docstring).

    Raises:
      DataError: a workdir has no (readable) metrics.jsonl or none with ``metric``, the labels do not match,
        or the output type or folder is wrong.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxgest.bench.train_compare import read_metrics
    from jaxgest.runtime.io import atomic_output, check_output_path

    out = pathlib.Path(out)
    if out.suffix.lower() not in PLOT_SUFFIXES:
        kind = out.suffix or "(no extension)"
        raise DataError(f"{out}: unknown image type {kind!r}; use .png, .svg or .pdf")
    out = check_output_path(out)
    workdirs = [pathlib.Path(w) for w in workdirs]
    labels = list(labels) if labels is not None else [w.name or str(w) for w in workdirs]
    if len(labels) != len(workdirs):
        raise DataError(f"--labels has {len(labels)} entries for {len(workdirs)} workdirs")
    runs = []
    for w in workdirs:
        c = curves(read_metrics(w), metric)
        if not c:
            raise DataError(f"{w / 'metrics.jsonl'}: no '{metric}' logged (metrics: "
                            f"{', '.join(_names(read_metrics(w))) or 'none'})")
        runs.append(c)
    stages = list(dict.fromkeys(s for c in runs for s in c))
    fig, axes = plt.subplots(1, len(stages), figsize=(5.2 * len(stages), 3.8), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, stage in zip(axes[0], stages):
        for k, (label, c) in enumerate(zip(labels, runs)):
            if stage not in c:
                continue
            color = colors[k % len(colors)]
            steps, values = c[stage]["train"]
            if steps:
                ax.plot(steps, values, color=color, lw=1.6, label=f"{label} train")
            steps, values = c[stage]["eval"]
            if steps:
                ax.plot(steps, values, color=color, lw=1.4, ls="--", marker="o", ms=3,
                        label=f"{label} held-out")
        ax.set_title(stage or "training")
        ax.set_xlabel("step")
        ax.set_ylabel(metric)
        if log_y:
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_output(out) as tmp:
        fig.savefig(tmp, format=out.suffix.lower().lstrip("."), dpi=110)
    plt.close(fig)
    return out


def _names(rows) -> list:
    skip = {"step", "stage", "devices", "platform", "processes"}
    return sorted({k for r in rows for k, v in r.items() if k not in skip and isinstance(v, (int, float))})


def _plot(args) -> int:
    labels = [s.strip() for s in args.labels.split(",")] if args.labels else None
    print(plot_training_curves(args.workdirs, args.out, metric=args.metric, labels=labels, log_y=args.log_y))
    return 0

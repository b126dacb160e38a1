"""One training run end to end at two commits, same data, seed and machine: wall times and loss curves.

``python -m jaxgest.bench.train_compare --before REV --after REV --out DIR [--png FILE] [--json FILE] -- TRAIN...``
(``--table RESULTS``: only the Markdown table of such a results file, for the docs)

``TRAIN...`` is a ``jaxgest`` training command without ``--workdir`` (e.g. ``zeggs train --data D --preset
small --steps 8000 --seed 0``). Each side runs ``python -m jaxgest.cli TRAIN... --workdir DIR/<side>`` with
the package of that commit (a ``git worktree`` in ``DIR/src-<side>`` on ``PYTHONPATH``; paths in ``TRAIN`` made
absolute, since a side runs in ``DIR``), one after the other,
nothing else started by this tool beside it; the wall time is the whole process (data loading and
compilation included). A side whose ``DIR/<side>/wall.json`` exists is not rerun (resume after an
interruption; delete the file to rerun).

Reported per side: wall seconds, steps, steps/s, the final loss (mean of the last ``--tail`` of the logged
losses, with its standard error over those log points) and the commit; the ratio before / after. The PNG
overlays the two loss curves (each logged loss, light; a running mean over ``--smooth`` log points, bold).
The results file is stamped (:mod:`jaxgest.runtime.provenance`).

A training run's loss is logged every 50 steps (since issue 60 the mean over those steps; one batch's before):
the final-loss comparison reads the mean of the tail, and "within the seed-to-seed spread" needs runs of other seeds (``--seeds-of``: further
workdirs of the same command with other seeds, whose final losses give the spread).
References: issue 41 (training runs before / after, same machine, same seed).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shlex
import subprocess
import sys
import time

from jaxgest.runtime.errors import DataError


def read_metrics(workdir) -> list[dict]:
    """The JSON lines of ``workdir/metrics.jsonl`` (every stage: a TGST run logs its autoencoder and its
    transformer stages in one file, each line with its ``stage`` when it has one)."""
    path = pathlib.Path(workdir) / "metrics.jsonl"
    if not path.is_file():
        raise DataError(f"{path}: no metrics.jsonl (did the training run write its workdir there?)")
    rows = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            raise DataError(f"{path}:{i}: not a JSON line") from None
    return rows


def loss_curves(rows: list[dict], key: str = "loss") -> dict[str, tuple[list[int], list[float]]]:
    """``{stage: (steps, losses)}`` from metrics rows (stage ``""`` when the rows name none)."""
    out: dict[str, tuple[list[int], list[float]]] = {}
    for r in rows:
        if key in r and "step" in r:
            s, v = out.setdefault(str(r.get("stage", "")), ([], []))
            s.append(int(r["step"]))
            v.append(float(r[key]))
    return out


def tail_mean(values: list[float], tail: int) -> tuple[float, float]:
    """Mean and standard error of the last ``tail`` values (:func:`jaxgest.zeggs.probes.mean_se`)."""
    from jaxgest.zeggs.probes import mean_se

    if not values:
        raise ValueError("no values")
    r = mean_se(values[-tail:])
    return r["mean"], r["standard_error"]


def _git(args, cwd):
    out = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True)
    if out.returncode:
        raise DataError(f"git {' '.join(args)}: {out.stderr.strip().splitlines()[-1] if out.stderr else 'failed'}")
    return out.stdout.strip()


def absolute_paths(train: list[str]) -> list[str]:
    """``train`` with every argument that names an existing file or folder (from the caller's directory) made
    absolute: a side runs in ``--out`` (so that ``python -m`` imports the commit's worktree, not the package in
    the caller's directory), where a relative ``--data ../shared/...`` would not resolve."""
    return [str(pathlib.Path(a).resolve()) if not a.startswith("-") and os.path.exists(a) else a for a in train]


def run_side(name: str, rev: str, out: pathlib.Path, train: list[str], repo: pathlib.Path) -> dict:
    """Train one side (skipped when its wall.json exists) and return its wall.json."""
    workdir, wall_file = out / name, out / name / "wall.json"
    if wall_file.is_file():
        return json.loads(wall_file.read_text())
    commit = _git(["rev-parse", f"{rev}^{{commit}}"], repo)
    src = out / f"src-{name}"
    if not src.is_dir():
        _git(["worktree", "add", "--detach", "-f", str(src), commit], repo)
    elif _git(["rev-parse", "HEAD"], src) != commit:
        _git(["checkout", "-q", "--detach", commit], src)
    cmd = [sys.executable, "-m", "jaxgest.cli", *absolute_paths(train), "--workdir", str(workdir)]
    env = {**os.environ, "PYTHONPATH": str(src) + (os.pathsep + os.environ["PYTHONPATH"]
                                                  if os.environ.get("PYTHONPATH") else "")}
    workdir.mkdir(parents=True, exist_ok=True)
    print(f"{name} ({commit[:9]}): {shlex.join(cmd)}", flush=True)
    t = time.perf_counter()
    with open(out / f"train_{name}.log", "w") as log:
        rc = subprocess.run(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=out).returncode
    wall = time.perf_counter() - t
    if rc:
        raise DataError(f"{out / f'train_{name}.log'}: the {name} run failed (exit {rc})")
    rec = {"seconds": wall, "commit": commit, "command": shlex.join(cmd), "timed_by": "train_compare"}
    wall_file.write_text(json.dumps(rec, indent=1))
    return rec


def summarize(workdir, wall: dict, tail: int) -> dict:
    curves = loss_curves(read_metrics(workdir))
    stages = {}
    for stage, (steps, losses) in curves.items():
        m, se = tail_mean(losses, tail)
        stages[stage or "train"] = {"steps": steps[-1], "final_loss": m, "final_loss_se": se,
                                    "tail": min(tail, len(losses))}
    steps = sum(s["steps"] for s in stages.values())
    return {"commit": wall["commit"], "wall_s": wall["seconds"], "steps": steps,
            "steps_per_s": steps / wall["seconds"], "stages": stages}


def markdown_table(res: dict) -> str:
    """The before / after table of a results file's ``results`` (``--table FILE``): wall, steps/s, each stage's
    final loss ± SE, the speed-up, and the other seeds' final losses when there are some."""
    stages = list(res["before"]["stages"])
    head = ["run", "commit", "wall", "steps/s"] + [f"final loss, {st}" for st in stages]
    rows = [head, ["---"] * 2 + ["---:"] * (len(head) - 2)]
    for name in ("before", "after"):
        r = res[name]
        rows.append([name, r["commit"][:7], f"{r['wall_s']:,.0f} s", f"{r['steps_per_s']:.2f}"]
                    + [f"{r['stages'][st]['final_loss']:.4f} ± {r['stages'][st]['final_loss_se']:.4f}"
                       for st in stages])
    for seed, finals in sorted(res.get("other_seeds", {}).items()):
        rows.append([f"{seed} (after's code)", "", "", ""] + [f"{finals[st]:.4f}" if st in finals else "-"
                                                               for st in stages])
    lines = ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines + ["", f"Speed-up (wall, before / after): **{res['speedup']:.2f}x**."])


def plot(sides: dict[str, pathlib.Path], png, smooth: int, title: str):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = {name: loss_curves(read_metrics(w)) for name, w in sides.items()}
    stages = sorted({s for c in curves.values() for s in c})
    fig, axes = plt.subplots(1, len(stages), figsize=(6.5 * len(stages), 4), squeeze=False)
    for ax, stage in zip(axes[0], stages):
        for (name, c), color in zip(curves.items(), ("tab:blue", "tab:orange", "tab:green", "tab:red")):
            if stage not in c:
                continue
            steps, losses = c[stage]
            ax.plot(steps, losses, color=color, alpha=0.25, lw=0.8)
            run = [sum(losses[max(0, i - smooth + 1):i + 1]) / len(losses[max(0, i - smooth + 1):i + 1])
                   for i in range(len(losses))]
            ax.plot(steps, run, color=color, lw=1.8, label=name)
        ax.set_yscale("log")
        ax.set_xlabel("step")
        ax.set_ylabel("training loss (log scale)")
        ax.set_title(f"{title} {stage}".strip() if len(stages) > 1 else title)
        ax.legend()
    fig.tight_layout()
    pathlib.Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    train = argv[argv.index("--") + 1:] if "--" in argv else []
    ap = argparse.ArgumentParser(prog="python -m jaxgest.bench.train_compare", description=__doc__.split("\n")[0])
    ap.add_argument("--before", help="commit (or any git revision) of the 'before' run")
    ap.add_argument("--after", default="HEAD", help="commit of the 'after' run (default HEAD)")
    ap.add_argument("--out", help="folder for the worktrees, workdirs and logs")
    ap.add_argument("--png", help="overlaid loss curves")
    ap.add_argument("--json", help="stamped results file")
    ap.add_argument("--tail", type=int, default=20, help="final loss = mean of the last N logged losses")
    ap.add_argument("--smooth", type=int, default=10, help="running mean over N log points in the plot")
    ap.add_argument("--seeds-of", nargs="*", default=[],
                    help="workdirs of other seeds (the spread of final losses)")
    ap.add_argument("--title", default="")
    ap.add_argument("--table", metavar="RESULTS", help="only print the Markdown table of a results file")
    a = ap.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    if a.table:
        from jaxgest.runtime.provenance import read_results
        try:
            print(markdown_table(read_results(a.table)["results"]))
        except DataError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        return 0
    if not a.before or not a.out:
        ap.error("--before and --out are required (or --table RESULTS)")
    if not train:
        ap.error("give the training command after --, e.g. -- zeggs train --data D --preset small --seed 0")
    repo = pathlib.Path(__file__).resolve().parents[2]
    out = pathlib.Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    try:
        walls = {name: run_side(name, rev, out, train, repo)
                 for name, rev in (("before", a.before), ("after", a.after))}
        res = {name: summarize(out / name, walls[name], a.tail) for name in walls}
        res["speedup"] = res["before"]["wall_s"] / res["after"]["wall_s"]
        if a.seeds_of:
            finals = {}
            for w in a.seeds_of:
                c = loss_curves(read_metrics(w))
                finals[pathlib.Path(w).name] = {st or "train": tail_mean(v, a.tail)[0] for st, (_, v) in c.items()}
            res["other_seeds"] = finals
        if a.png:
            plot({f"{k} ({walls[k]['commit'][:7]}, {res[k]['wall_s']:.0f} s)": out / k for k in walls}, a.png,
                 a.smooth, a.title)
    except DataError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for name in ("before", "after"):
        r = res[name]
        finals = ", ".join(f"{st} {s['final_loss']:.4f} ± {s['final_loss_se']:.4f}"
                           for st, s in r["stages"].items())
        print(f"{name}: {r['commit'][:9]} {r['wall_s']:.0f} s, {r['steps_per_s']:.2f} steps/s, "
              f"final loss {finals}")
    print(f"speed-up (wall, before / after): {res['speedup']:.3f}x")
    if a.json:
        from jaxgest.runtime.provenance import process_command, write_results
        write_results(a.json, res, {"before": a.before, "after": a.after, "train": train, "tail": a.tail},
                      process_command(["python", "-m", "jaxgest.bench.train_compare", *argv]))
    return 0


if __name__ == "__main__":
    sys.exit(main())

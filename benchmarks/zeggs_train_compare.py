"""Two short ZeroEGGS trainings that must give the same loss curve, one without and one with a speed lever.

``python -m benchmarks.zeggs_train_compare --data DIR [--preset small] [--steps 60] [--log-every 10]
[--workdir /tmp/zcmp] [--out x.json] [--reverse]``

Runs ``jaxgest.zeggs.train.train`` twice from scratch, same seed and data: ``before`` with
``prefetch=0`` (batches built on the loop's thread) and ``after`` with ``prefetch=1`` (built ahead on a
worker thread, :mod:`jaxgest.prefetch`). Reports each run's wall time (compilation included: the same in
both), the steady-state seconds per step from ``metrics.jsonl`` (``steps_per_s`` of the log steps after
the first), and whether every logged loss is bit-equal. On a shared machine the times move with the load;
the equality does not.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import shutil
import statistics
import sys


def _run(data, workdir, preset, steps, log_every, prefetch):
    from jaxgest.zeggs.train import train

    shutil.rmtree(workdir, ignore_errors=True)
    summary = train(data, workdir, preset=preset, steps=steps, seed=0, progress=False, log_every=log_every,
                    ckpt_every=steps, prefetch=prefetch)
    rows = [json.loads(line) for line in (pathlib.Path(workdir) / "metrics.jsonl").read_text().splitlines()]
    rates = [r["steps_per_s"] for r in rows[1:] if r.get("steps_per_s")]
    return {"wall_s": summary["wall_s"], "s_per_step": 1.0 / statistics.median(rates) if rates else None,
            "losses": [r["loss"] for r in rows]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.zeggs_train_compare", description=__doc__.split("\n")[0])
    p.add_argument("--data", required=True)
    p.add_argument("--preset", default="small")
    p.add_argument("--steps", type=int, default=60)
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--workdir", default="/tmp/zeggs_train_compare")
    p.add_argument("--out", default=None)
    p.add_argument("--reverse", action="store_true", help="run `after` first (an ordering control)")
    a = p.parse_args(argv)
    res = {}
    runs = (("before", 0), ("after", 1))
    for name, prefetch in (runs[::-1] if a.reverse else runs):
        res[name] = _run(a.data, f"{a.workdir}/{name}", a.preset, a.steps, a.log_every, prefetch)
        print(name, {k: v for k, v in res[name].items() if k != "losses"}, flush=True)
    res["losses_bit_equal"] = res["before"]["losses"] == res["after"]["losses"]
    res["load_avg_1m"] = __import__("os").getloadavg()[0]
    text = json.dumps(res, indent=2)
    if a.out:  # a stamped results file (commit, version, config, command)
        from jaxgest.provenance import write_results

        write_results(a.out, res, {"preset": a.preset, "steps": a.steps, "log_every": a.log_every, "data": a.data, "reverse": a.reverse}, ["python", "-m", __spec__.name] + list(sys.argv[1:] if argv is None else argv))
    print(text)
    return 0 if res["losses_bit_equal"] else 1


if __name__ == "__main__":
    sys.exit(main())

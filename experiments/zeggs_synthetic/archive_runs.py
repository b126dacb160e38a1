"""Archive the ``evaluate`` JSONs of trained runs into ``out/window_runs.json`` (the committed record; the
per-run files under ``out/`` are not committed): keys ``<run>``, ``<run>_heldout``, ``pooled_<run>``.

    python experiments/zeggs_synthetic/archive_runs.py out RUN [RUN ...]

Reads ``out/eval_<run>.json``, ``out/eval_<run>_heldout.json`` and ``out/eval_pooled_<run>.json`` (written by
``eval_run.sh``); an existing key is replaced. ``initial_pose_table.py`` and ``seed_rule.py`` read either.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def main() -> int:
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    out = Path(sys.argv[1])
    path = out / "window_runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else {}
    for run in sys.argv[2:]:
        for key, name in ((run, f"eval_{run}"), (f"{run}_heldout", f"eval_{run}_heldout"),
                          (f"pooled_{run}", f"eval_pooled_{run}")):
            f = out / f"{name}.json"
            if not f.is_file():
                raise SystemExit(f"archive_runs: {f} is missing (run eval_run.sh {run} first)")
            runs[key] = json.loads(f.read_text())
    path.write_text(json.dumps(runs, indent=1))
    print(f"{path}: {len(runs)} keys")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""One training folder from several `jaxgest synth` folders (more scripts of the same contents and styles).

    python experiments/zeggs_synthetic/merge_scripts.py OUT SEED=FOLDER [SEED=FOLDER ...]
    # e.g. out/data_x4 0=out/data 17=out/data_s17 18=out/data_s18 19=out/data_s19

Each clip is linked (symlink, no copy) as ``{stem}s{SEED}.bvh`` / ``.wav`` and listed in ``OUT/manifest.csv`` with
its own content and style labels, so a content label covers that content's scripts of every seed.
"""
from __future__ import annotations

import csv
import os
import pathlib
import sys


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 2 or any("=" not in a for a in argv[1:]):
        sys.exit(__doc__)
    out = pathlib.Path(argv[0])
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for arg in argv[1:]:
        seed, folder = arg.split("=", 1)
        folder = pathlib.Path(folder)
        with open(folder / "manifest.csv", newline="") as f:
            for r in csv.DictReader(f):
                stem = r["path"][:-len(".bvh")] + f"s{seed}"
                for ext, key in ((".bvh", "path"), (".wav", "audio")):
                    dst = out / f"{stem}{ext}"
                    if not dst.exists():
                        os.symlink((folder / r[key]).resolve(), dst)
                rows.append({"path": f"{stem}.bvh", "content": r["content"], "style": r["style"],
                             "audio": f"{stem}.wav"})
    with open(out / "manifest.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["path", "content", "style", "audio"])
        w.writeheader()
        w.writerows(rows)
    print(f"{out}: {len(rows)} clips")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

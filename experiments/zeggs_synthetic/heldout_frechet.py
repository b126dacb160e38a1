"""The held-out Fréchet distance over many script seeds, against the floor and against real other-script motion.

    python experiments/zeggs_synthetic/heldout_frechet.py --workdir W --datasets D1 D2 ... [--json OUT]

Each Di is a `jaxgest synth --seed K` folder the model was not trained on. For each: the model generates the
test clips of the `jaxgest zeggs evaluate` split from their speech (style example and seed as `evaluate`,
default temperature) and the Fréchet distance to the real test clips is computed (root-frame joint
positions and velocities per frame), beside (1) the floor of `evaluate` (the real train half against the
test half of Di) and (2) the real clips of the same contents and styles from every other Dj (scripts the
model and Di share nothing of but the content and style labels; `script_floor.py`). Prints per dataset and,
over datasets, the geometric mean of model / floor and of model / median other-script distance, with the
paired log ratio's standard error over datasets.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def main(argv=None) -> int:
    from tqdm.auto import tqdm

    from jaxgest.motion.datasets import load_clip_audio
    from jaxgest.zeggs import evaluate as ev
    from jaxgest.zeggs.inference import load_model
    from script_floor import frechet, other_script_distance, test_split

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True), ap.add_argument("--datasets", nargs="+", required=True)
    ap.add_argument("--seed", type=int, default=0), ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)

    feats = ev.motion_statistics_features
    model = load_model(a.workdir)
    rows = []
    for d in a.datasets:
        train, test, real, floor = test_split(d, a.seed)
        gen = []
        for c in tqdm(test, desc=str(d), leave=False):
            audio, sr = load_clip_audio(c)
            gen.append(feats(model.generate(audio, [ev.style_example(c, train).motion], sr=sr, seed=a.seed)))
        model_fd = frechet(np.concatenate(gen), real)
        others = [other_script_distance(test, real, o) for o in a.datasets if o != d]
        rows.append({"data": d, "floor": floor, "model": model_fd, "other_scripts": others,
                     "other_median": float(np.median(others))})
        print(f"{d}: floor {floor:.0f}, model {model_fd:.0f} ({model_fd / floor:.2f}x), real other scripts median "
              f"{np.median(others):.0f} ({np.median(others) / floor:.2f}x; range {min(others):.0f}-{max(others):.0f})",
              flush=True)
    lf = np.log([r["model"] / r["floor"] for r in rows])
    lo = np.log([r["model"] / r["other_median"] for r in rows])
    of = np.log([r["other_median"] / r["floor"] for r in rows])
    se = lambda x: float(x.std(ddof=1) / np.sqrt(len(x)))  # noqa: E731
    print(f"\nover {len(rows)} datasets (geometric means): model / floor {np.exp(lf.mean()):.2f}x "
          f"(per dataset {np.exp(lf.min()):.2f}-{np.exp(lf.max()):.2f}); real other scripts / floor "
          f"{np.exp(of.mean()):.2f}x; model / real other scripts {np.exp(lo.mean()):.2f}x "
          f"(log ratio {lo.mean():+.3f} +- {se(lo):.3f}, model lower on {int((lo < 0).sum())}/{len(lo)})")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"workdir": a.workdir, "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""An upper bound on any window feature's accuracy on the handedness pair (``neutral`` / ``left_handed``).

The two styles share every parameter but the hand of one-handed ("dominant") strokes
(``jaxgest/motion/synthetic/styles.py``), and a content's script (stroke kinds, apex times, which strokes use
both hands) does not depend on the style (``content.py``). Both-hand strokes move the two hands alike and the
idle motion is the same in both styles, so a probe window that no one-handed stroke touches is drawn from the
same distribution in both styles: no classifier beats 1/2 on such windows averaged over the pair. A window
counts as decidable if the two styles' noise-free stroke tracks (``strokes.stroke_tracks``: both hands'
targets and shrugs, smoothed as ``render_clip`` smooths them) differ anywhere in it by more than 1e-6 (cm);
this covers each stroke's lead from rest, the smoothing's spread and retractions cut by the next stroke. The
expected pair accuracy of *any* window feature is then at most ``f + (1 - f) / 2``, ``f`` the share of
decidable windows (a bound on the expectation: a finite set of correlated windows can land above it by
chance). The probe's windows: 2 s every 0.5 s (``jaxgest.zeggs.probes``), clips of ``jaxgest synth --seed K``
(10 s, 60 fps).

With ``--workdir W --data D1 ...`` (the pooled probe datasets, in seed order) it also measures, per content,
the raw-statistics probe's accuracy on the pair (the 7-style probe of ``probe_confusion.py``, same folds) beside
the bound: a check that the bound holds and that the raw statistics fail where no one-handed stroke is.

Usage (from experiments/zeggs_synthetic/):
    python handedness_ceiling.py --seeds 1-16 [--json out/handedness_ceiling.json] \
        [--workdir out/ipz20_8k --data out/probe_data/seed{1..16}]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

from jaxgest.motion.synthetic import smooth
from jaxgest.motion.synthetic.content import CONTENTS, make_script
from jaxgest.motion.synthetic.strokes import stroke_tracks
from jaxgest.motion.synthetic.styles import STYLES
from jaxgest.zeggs.probes import PROBE_STRIDE_S, PROBE_WINDOW_S


def style_difference(script, t, fps: float) -> np.ndarray:
    """Per frame, the largest difference between the ``neutral`` and ``left_handed`` noise-free stroke tracks."""
    a, b = STYLES["neutral"], STYLES["left_handed"]
    assert a.smoothness == b.smoothness and a.tremor == b.tremor == 0.0
    ta, tb = stroke_tracks(script, a, t), stroke_tracks(script, b, t)
    d = np.zeros(len(t))
    for side in ("L", "R"):
        for key in ("hand", "shrug"):
            x, y = smooth(ta[key][side], a.smoothness, fps), smooth(tb[key][side], b.smoothness, fps)
            d = np.maximum(d, np.abs(x - y).reshape(len(t), -1).max(axis=1))
    return d


def decidable_share(seed: int, seconds: float = 10.0, fps: float = 60.0, eps: float = 1e-6) -> dict:
    """Per content of dataset ``seed``: the share of probe windows in which the two styles' tracks differ."""
    n, stride, frames = int(PROBE_WINDOW_S * fps), int(PROBE_STRIDE_S * fps), int(round(seconds * fps))
    t = np.arange(frames) / fps
    out = {}
    for name, spec in CONTENTS.items():
        d = style_difference(make_script(spec.with_seed(seed, seconds)), t, fps)
        out[name] = float(np.mean([d[s:s + n].max() > eps for s in range(0, frames - n + 1, stride)]))
    return out


def raw_pair_by_content(workdir, data) -> dict:
    """The raw-statistics style probe's mean per-clip accuracy on ``neutral`` / ``left_handed`` clips, per content."""
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import probes
    from jaxgest.zeggs.inference import load_model

    model = load_model(workdir)
    clips = [c for d in data for c in load_folder(d)]
    labels, contents = [c.style for c in clips], [c.content for c in clips]
    raws = [probes.statistics_windows(model, c, PROBE_WINDOW_S, stride_s=PROBE_STRIDE_S) for c in clips]
    preds = probes.fold_predictions(raws, labels, contents)
    acc = [np.mean([q == y for q in p]) for p, y in zip(preds, labels)]
    return {c: float(np.mean([a for a, y, k in zip(acc, labels, contents)
                              if k == c and y in ("neutral", "left_handed")])) for c in CONTENTS}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-16", help="dataset seeds, e.g. 1-16")
    ap.add_argument("--json", type=pathlib.Path, default=None)
    ap.add_argument("--workdir", help="a trained run (its normalisation) to measure the raw statistics' pair accuracy")
    ap.add_argument("--data", nargs="*", default=[], help="the probe datasets of --seeds, in the same order")
    args = ap.parse_args(argv)
    lo, _, hi = args.seeds.partition("-")
    seeds = list(range(int(lo), int(hi or lo) + 1))
    per = {k: decidable_share(k) for k in seeds}
    f = np.array([v for d in per.values() for v in d.values()])  # one value per (dataset, content)
    bound = f + (1 - f) / 2
    res = {"seeds": seeds, "decidable_share": {str(k): v for k, v in per.items()},
           "decidable_share_mean": float(f.mean()), "pair_accuracy_bound_mean": float(bound.mean()),
           "pair_accuracy_bound_se": float(bound.std(ddof=1) / np.sqrt(len(bound)))}
    by_content = {c: float(np.mean([per[k][c] for k in seeds])) for c in CONTENTS}
    print(f"probe windows where the two styles' stroke tracks differ: {f.mean():.3f} (over {len(seeds)} datasets x "
          f"{len(CONTENTS)} contents); by content: " + ", ".join(f"{c} {v:.2f}" for c, v in by_content.items()))
    print(f"upper bound on any window feature's handedness-pair accuracy: {bound.mean():.3f} "
          f"± {res['pair_accuracy_bound_se']:.3f} (SE over dataset x content)")
    if args.workdir:
        res["raw_statistics_pair_accuracy_by_content"] = raw_pair_by_content(args.workdir, args.data)
        print("| content | share decidable | bound | raw statistics, pair accuracy |\n|---|---:|---:|---:|")
        for c in CONTENTS:
            b = by_content[c] + (1 - by_content[c]) / 2
            print(f"| {c} | {by_content[c]:.2f} | {b:.3f} | {res['raw_statistics_pair_accuracy_by_content'][c]:.3f} |")
    if args.json:
        args.json.write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

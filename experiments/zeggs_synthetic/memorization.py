"""Does the generator follow the new speech, or replay the training clip of the same content and style?

    python experiments/zeggs_synthetic/memorization.py --workdir W --train-data D_TRAIN --data D_HELDOUT [--json OUT]

The synthetic clips of one content and style differ between script seeds only in their scripts (stroke
times and kinds, and the speech rendered from them). For every test clip of the held-out split (the split
and style example of ``jaxgest zeggs evaluate``), the motion generated from its speech is compared frame by
frame (root-frame hand positions, cm, the same frame count) with (a) its own real motion and (b) the
training clip of the same content and style (another script); the control is (c) the real held-out clip
against that training clip; with ``--other-data`` (a third script seed) also (d) the generated motion against
that seed's clip of the same content and style, which the model never saw. A generator that follows the speech is closer to (a) than to (d); one that replays what it
saw in training is closer to (b) than to (d) by more than the real held-out clip is (the difference of the
differences). Also the same with the speech of the training clip (the generated motion
against its real motion: how well the model reproduces a clip it was trained on).
Prints per-clip means with standard errors and the paired difference (a) - (b).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def hands(motion):
    from jaxgest.motion import body, kinematics

    pos = kinematics.root_local_positions(motion)
    return pos[:, body.joint_indices(motion.skeleton, body.HANDS)].reshape(len(pos), -1)


def dist(a, b) -> float:
    n = min(len(a), len(b))
    return float(np.linalg.norm((a[:n] - b[:n]).reshape(n, -1, 3), axis=-1).mean())


def main(argv=None) -> int:
    from jaxgest.motion.datasets import load_clip_audio, load_folder
    from jaxgest.zeggs import evaluate as ev
    from jaxgest.zeggs.inference import load_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True), ap.add_argument("--train-data", required=True)
    ap.add_argument("--data", required=True), ap.add_argument("--json", default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--other-data", default=None, help="a third script seed (neither trained on nor the test "
                    "clip's): the control (d) generated vs its clip of the same content and style")
    a = ap.parse_args(argv)
    model = load_model(a.workdir)
    clips = [c for c in load_folder(a.data) if c.audio is not None]
    trained = {(c.content, c.style): c for c in load_folder(a.train_data) if c.audio is not None}
    other = {(c.content, c.style): c for c in load_folder(a.other_data)} if a.other_data else {}
    train, test = ev._split_by_style(clips, a.seed)
    rows = []
    for c in test:
        t = trained.get((c.content, c.style))
        if t is None:
            continue
        audio, sr = load_clip_audio(c)
        ex = ev.style_example(c, train).motion
        g = hands(model.generate(audio, [ex], sr=sr, seed=a.seed))
        audio_t, sr_t = load_clip_audio(t)
        g_t = hands(model.generate(audio_t, [ex], sr=sr_t, seed=a.seed))
        real, real_t = hands(c.motion), hands(t.motion)
        rows.append({"clip": str(c.path.name), "own": dist(g, real), "training_clip": dist(g, real_t),
                     "real_vs_training_clip": dist(real, real_t), "train_speech_own": dist(g_t, real_t)})
        o = other.get((c.content, c.style))
        if o is not None:
            rows[-1].update(other_script=dist(g, hands(o.motion)), real_vs_other_script=dist(real, hands(o.motion)))
    keys = ("own", "training_clip", "real_vs_training_clip", "train_speech_own") + \
        (("other_script", "real_vs_other_script") if other else ())
    print(f"{len(rows)} held-out test clips; mean hand distance per frame (cm) +- SE over clips:")
    for k in keys:
        x = np.array([r[k] for r in rows])
        print(f"  {k:24s} {x.mean():7.2f} +- {x.std(ddof=1) / np.sqrt(len(x)):.2f}")
    d = np.array([r["own"] - r["training_clip"] for r in rows])
    print(f"  (a) own - (b) training clip: {d.mean():+.2f} +- {d.std(ddof=1) / np.sqrt(len(d)):.2f} "
          f"(closer to its own motion on {int((d < 0).sum())}/{len(d)})")
    if other:
        d = np.array([r["training_clip"] - r["other_script"] for r in rows])
        print(f"  (b) training clip - (d) other script: {d.mean():+.2f} +- {d.std(ddof=1) / np.sqrt(len(d)):.2f} "
              f"(closer to the training clip on {int((d < 0).sum())}/{len(d)})")
        q = np.array([r["real_vs_training_clip"] - r["real_vs_other_script"] for r in rows])
        dd = d - q
        print(f"  the same for the real held-out clip: {q.mean():+.2f}; difference of the differences (what a "
              f"replay adds): {dd.mean():+.2f} +- {dd.std(ddof=1) / np.sqrt(len(dd)):.2f} ({int((dd < 0).sum())}/{len(dd)})")
        o = np.array([r["own"] - r["other_script"] for r in rows])
        print(f"  (a) own - (d) other script: {o.mean():+.2f} +- {o.std(ddof=1) / np.sqrt(len(o)):.2f} "
              f"(closer to its own on {int((o < 0).sum())}/{len(o)})")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"workdir": a.workdir, "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

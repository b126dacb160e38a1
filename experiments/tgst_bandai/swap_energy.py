"""How much the soft and hard swaps' outputs move, against the style clip: arm speed and its window spread.

    python experiments/tgst_bandai/swap_energy.py EVAL_DIR TRIM WORKDIR... [--seeds 0,1,2] [--json OUT]

For every held-out pair (intra and inter) and workdir: the arm-joint velocities of the authors' protocol
(`jaxgest.tgst.protocol.clip_features`, TRIM-second cut) of the soft swap, the hard swap, the plain
autoencoder round trip of the content, the content clip and the style clip; per clip the mean arm speed
(m/s, mean over frames and the 8 arm joints of the velocity norm) and the mean over 128-frame windows of the
per-joint velocity std (the D_std side of eq. 15). Prints, per pair mode, each output's ratio to the style
clip (geometric mean over pairs, seeds averaged per pair) and soft minus hard of log-ratios (+- SE over pairs).
"""
import argparse
import json
import sys

import numpy as np

from jaxgest import metrics
from jaxgest.tgst.api import load_model
from jaxgest.tgst.batched import BatchedTransfer
from jaxgest.tgst.evaluate import _load_pairs
from jaxgest.tgst.protocol import clip_features, get_protocol


def energy(vel: np.ndarray, window: int) -> tuple[float, float]:
    """(mean arm speed, mean over half-overlapping windows of the per-joint velocity std summed over axes)."""
    v = vel.reshape(len(vel), -1, 3)
    speed = float(np.linalg.norm(v, axis=-1).mean())
    stds = [np.linalg.norm(v[h:h + window].std(axis=0), axis=-1).mean()
            for h in range(0, max(len(v) - window, 1), window // 2)]
    return speed, float(np.mean(stds))


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("eval_dir"), ap.add_argument("trim", type=float), ap.add_argument("workdirs", nargs="+")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv[1:])
    proto = get_protocol("authors", a.trim)
    out = {}
    for mode in ("intra", "inter"):
        pairs = _load_pairs(a.eval_dir, mode, None, None, 0, False)
        rows = {}  # pair index -> name -> list over workdirs of (speed, std)
        fixed = {}
        for wd in a.workdirs:
            model = load_model(wd)
            bt = BatchedTransfer(model, ("soft", "hard", "autoencoder"))
            for i, pair in enumerate(pairs):
                fps = pair.content.motion.fps
                window = metrics.window_for_fps(fps)
                try:
                    res, _ = bt.run(pair)
                    feats = {m: clip_features(res[m], fps, proto)[1] for m in ("soft", "hard", "autoencoder")}
                    if i not in fixed:
                        fixed[i] = {"content": energy(clip_features(pair.content.motion, fps, proto)[1], window),
                                    "style": energy(clip_features(pair.style.motion, fps, proto)[1], window)}
                except Exception as e:  # too short for the cut: skipped as in evaluate
                    print(f"skip {mode} {i}: {e}", file=sys.stderr)
                    continue
                for m, f in feats.items():
                    rows.setdefault(i, {}).setdefault(m, []).append(energy(f, window))
        keep = sorted(i for i in rows if i in fixed)
        res = {}
        for name in ("soft", "hard", "autoencoder", "content"):
            for k, label in ((0, "speed"), (1, "window_std")):
                if name == "content":
                    r = np.array([np.log(fixed[i]["content"][k] / fixed[i]["style"][k]) for i in keep])
                else:
                    r = np.array([np.log(np.mean([e[k] for e in rows[i][name]]) / fixed[i]["style"][k]) for i in keep])
                res[f"{name}_{label}"] = r
        print(f"\n{mode} ({len(keep)} pairs, {len(a.workdirs)} workdirs): ratio to the style clip (geometric mean)")
        print("| output | arm speed | window std |\n|---|---|---|")
        for name in ("soft", "hard", "autoencoder", "content"):
            print(f"| {name} | {np.exp(res[name + '_speed'].mean()):.3f} | {np.exp(res[name + '_window_std'].mean()):.3f} |")
        for k in ("speed", "window_std"):
            d = res[f"soft_{k}"] - res[f"hard_{k}"]
            print(f"soft minus hard, log {k}: {d.mean():+.4f} +- {d.std(ddof=1) / np.sqrt(len(d)):.4f} "
                  f"(soft lower on {int((d < 0).sum())}/{len(d)})")
        out[mode] = {k: v.tolist() for k, v in res.items()}
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f)


if __name__ == "__main__":
    main(sys.argv)

"""Where the Fréchet distance of generated vs real motion comes from.

Regenerates the test clips exactly as ``jaxgest zeggs evaluate`` does (same split, style example and seed),
then splits the distance: the mean term ||mu_g - mu_r||^2 against the covariance term, root-frame joint
positions against velocities, the joints with the largest share of the mean term and of the variance
difference, and the total variance of generated vs real features (generated motion with too little or too
much movement shows there). Also the distance with the style embedding at temperature 0 (the posterior mean)
instead of the default sample (temperature 1), and the real-train vs real-test floor.

Usage: python experiments/zeggs_synthetic/frechet_diagnostic.py --workdir W --data D --json OUT.json
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np


def split(gen: np.ndarray, real: np.ndarray) -> dict:
    """Fréchet distance and its mean and covariance terms."""
    from jaxgest import metrics

    mg, cg = metrics.gaussian_statistics(gen)
    mr, cr = metrics.gaussian_statistics(real)
    total = metrics.frechet_distance_from_statistics(mg, cg, mr, cr)
    mean_term = float(np.sum((mg - mr) ** 2))
    return {"frechet": total, "mean_term": mean_term, "covariance_term": total - mean_term,
            "total_variance_generated": float(np.trace(cg)), "total_variance_real": float(np.trace(cr))}


def main(argv=None) -> int:
    from tqdm.auto import tqdm

    from jaxgest.motion.datasets import load_clip_audio, load_folder
    from jaxgest.zeggs import evaluate as ev
    from jaxgest.zeggs.inference import load_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    model = load_model(args.workdir)
    clips = load_folder(args.data)
    train, test = ev._split_by_style([c for c in clips if c.audio is not None], args.seed)
    real = [ev.motion_statistics_features(c.motion) for c in test]
    real_train = np.concatenate([ev.motion_statistics_features(c.motion) for c in train])
    J = clips[0].motion.skeleton.num_joints
    names = clips[0].motion.skeleton.names
    gen = {}
    for temp in (None, 0.0):
        key = "default temperature" if temp is None else f"temperature {temp:g}"
        feats = []
        for c in tqdm(test, desc=key, leave=False):
            audio, sr = load_clip_audio(c)
            m = model.generate(audio, [ev.style_example(c, train).motion], sr=sr, seed=args.seed, temperature=temp)
            feats.append(ev.motion_statistics_features(m))
        gen[key] = np.concatenate(feats)
    real_all = np.concatenate(real)
    out = {"workdir": str(args.workdir), "data": str(args.data), "test_clips": len(test),
           "default_temperature": model.cfg.inference.temperature,
           "features": "root-frame joint positions (3J) and velocities (3J), per frame", "by_variant": {}}
    pos, vel = slice(0, 3 * J), slice(3 * J, 6 * J)
    for key, g in list(gen.items()) + [("real train clips (the floor)", real_train)]:
        out["by_variant"][key] = {"all": split(g, real_all), "positions": split(g[:, pos], real_all[:, pos]),
                                  "velocities": split(g[:, vel], real_all[:, vel])}
    g = gen["default temperature"]
    dm = (g.mean(0) - real_all.mean(0)) ** 2
    dv = g.var(0, ddof=1) - real_all.var(0, ddof=1)
    per_joint = []
    for j in range(J):
        idx_p, idx_v = slice(3 * j, 3 * j + 3), slice(3 * J + 3 * j, 3 * J + 3 * j + 3)
        per_joint.append({"joint": names[j], "mean_term_positions": float(dm[idx_p].sum()),
                          "mean_term_velocities": float(dm[idx_v].sum()),
                          "variance_generated_minus_real_positions": float(dv[idx_p].sum()),
                          "variance_generated_minus_real_velocities": float(dv[idx_v].sum()),
                          "velocity_variance_ratio": float(g[:, idx_v].var(0).sum() / max(real_all[:, idx_v].var(0).sum(), 1e-12))})
    out["per_joint_default_temperature"] = sorted(per_joint, key=lambda r: -(r["mean_term_positions"]
                                                                             + r["mean_term_velocities"]))
    pathlib.Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    print("| features: generated vs real test clips | Fréchet | mean term | covariance term | total variance gen / real |")
    print("|---|---:|---:|---:|---:|")
    for key, parts in out["by_variant"].items():
        for part, r in parts.items():
            print(f"| {key}, {part} | {r['frechet']:.0f} | {r['mean_term']:.0f} | {r['covariance_term']:.0f} | "
                  f"{r['total_variance_generated']:.0f} / {r['total_variance_real']:.0f} |")
    print("\n| joint (largest mean term first) | mean term pos / vel | variance gen − real pos / vel | vel. var. ratio |")
    print("|---|---:|---:|---:|")
    for r in out["per_joint_default_temperature"][:8]:
        print(f"| {r['joint']} | {r['mean_term_positions']:.0f} / {r['mean_term_velocities']:.0f} | "
              f"{r['variance_generated_minus_real_positions']:.0f} / {r['variance_generated_minus_real_velocities']:.0f} | "
              f"{r['velocity_variance_ratio']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

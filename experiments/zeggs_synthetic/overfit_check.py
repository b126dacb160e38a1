"""Sanity measures of a ZeroEGGS model overfit on one real ZEGGS clip (experiments/zeggs_synthetic).

Generates gestures from the clip's own audio in the style of the clip itself and compares them, frame by
frame, with the captured motion: root-frame joint position error (cm) against two controls (the clip's
mean pose held still; the real clip shifted by half its length, i.e. real-looking motion that is not
aligned with the audio), the correlation of hand speeds, and BeatAlign against shuffled onsets.

Usage: python overfit_check.py --workdir W --data ZEGGS_DIR --json OUT.json [--out-bvh GEN.bvh]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from jaxgest.motion import bvh
from jaxgest.motion import kinematics as K
from jaxgest.motion.datasets import load_clip_audio, load_folder
from jaxgest.zeggs import features as Fe
from jaxgest.zeggs.evaluate import _hand_indices, beat_scores
from jaxgest.zeggs.inference import load_model
from jaxgest import metrics


def root_frame_positions(motion) -> np.ndarray:
    f = Fe.extract_features(motion)["features"]
    lay = Fe.PoseLayout(motion.skeleton.num_joints)
    return f[:, lay.local_positions].reshape(len(f), -1, 3)


def mean_distance(a, b) -> float:
    return float(np.mean(np.linalg.norm(a - b, axis=-1)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--json", required=True)
    ap.add_argument("--out-bvh", default=None)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    clip = [c for c in load_folder(args.data) if c.audio is not None][0]
    model = load_model(args.workdir)
    audio, sr = load_clip_audio(clip)
    real = clip.motion
    gen = model.generate(audio, [real], sr=sr, seed=args.seed, temperature=0.0, name="overfit_generated")
    if args.out_bvh:
        bvh.save(gen, args.out_bvh)
    F = min(gen.num_frames, real.num_frames)
    pg, pr = root_frame_positions(gen)[:F], root_frame_positions(real)[:F]
    shifted = np.roll(pr, F // 2, axis=0)
    hands = _hand_indices(real)
    sg = metrics.hand_speed(K.forward_kinematics(gen)[:F], gen.fps, hands)
    sr_ = metrics.hand_speed(K.forward_kinematics(real)[:F], real.fps, hands)
    corr = lambda a, b: float(np.corrcoef(a, b)[0, 1])  # noqa: E731
    lines = [json.loads(x) for x in open(f"{args.workdir}/metrics.jsonl")]
    result = {
        "clip": clip.path.name, "frames": int(F), "fps": real.fps, "joints": real.skeleton.num_joints,
        "root_frame_position_error_cm": {
            "generated_vs_real": mean_distance(pg, pr),
            "control_static_mean_pose": mean_distance(pr.mean(0, keepdims=True), pr),
            "control_real_shifted_half": mean_distance(shifted, pr),
        },
        "hand_speed_correlation": {"generated_vs_real": corr(sg, sr_),
                                   "control_real_shifted_half": corr(np.roll(sr_, F // 2), sr_)},
        "hand_speed_mean_cm_s": {"generated": float(sg.mean()), "real": float(sr_.mean())},
        "beat_alignment": {"generated": beat_scores(gen, audio, sr, seed=args.seed),
                           "real": beat_scores(real, audio, sr, seed=args.seed)},
        "training_loss": {"first_logged": lines[0]["loss"], "last_logged": lines[-1]["loss"],
                          "first_step": lines[0]["step"], "last_step": lines[-1]["step"]},
        "temperature": 0.0,
    }
    with open(args.json, "w") as fh:
        json.dump(result, fh, indent=2)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

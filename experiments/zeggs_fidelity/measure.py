"""Train one variant of ZeroEGGS on the built-in synthetic data and score it on held-out scripts.

Every variant: the same data (``jaxgest synth --seed 0``, 42 clips), seed, preset and steps; only the
config fields named by ``--variant`` differ. Scores: on 128 fixed windows of the held-out scripts
(``jaxgest synth --seed 1``; same normalisation statistics as the model, mirror/speed augmentation off),
the style embedding from a style window of the same clip, deterministic networks, the loss terms with the
rig in the config, so every variant is scored on the positions of the motion that is rendered (FK of the
predicted rotations): ``local_position`` (cm, character frame), ``world_position`` (cm), ``local_rotation``
(6-D), ``fd_local_position`` (cm/s). Per-window values go to ``OUT/<variant>.json``; ``compare.py`` pairs
them.

    python experiments/zeggs_fidelity/measure.py --variant base --steps 600 [--seed 1]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np

HERE = pathlib.Path(__file__).parent
NO_FK = {"fk_parents": (), "fk_offsets": (), "fk_translated": ()}
VARIANTS = {  # each adds one change to the one before it
    "base": {"loudness": False, **NO_FK, "input_norm": "channel"},
    "loudness": {"loudness": True, **NO_FK, "input_norm": "channel"},
    "fk": {"loudness": True, "input_norm": "channel"},
    "norm": {"loudness": True, "input_norm": "group"},
}
COMMON = {"batch_size": 16, "window": 64, "style_window_min": 64, "style_window_max": 128}
TERMS = ("local_position", "world_position", "local_rotation", "fd_local_position", "recon")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--variant", required=True, choices=sorted(VARIANTS))
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--out", default=str(HERE / "out"))
    ap.add_argument("--windows", type=int, default=128)
    ap.add_argument("--seed", type=int, default=0, help="training seed (initialisation, batches, dropout)")
    args = ap.parse_args()

    import jax

    from jaxgest.motion.datasets import load_folder
    from jaxgest.motion.synthetic import write_dataset
    from jaxgest.zeggs import data as zdata
    from jaxgest.zeggs import features
    from jaxgest.zeggs.config import field_names
    from jaxgest.zeggs.steps import loss_terms
    from jaxgest.zeggs.trainer import train
    from jaxgest.zeggs.workdir import load_workdir

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, seed in (("data", 0), ("data_heldout", 1)):
        if not (out / name / "manifest.csv").is_file():
            write_dataset(out / name, seed=seed, progress=False)
    fields = set().union(*field_names().values())
    overrides = {k: v for k, v in {**COMMON, **VARIANTS[args.variant]}.items() if k in fields}
    skipped = sorted(set(VARIANTS[args.variant]) - fields)
    name = args.variant if args.seed == 0 else f"{args.variant}_s{args.seed}"
    work = out / f"work_{name}"
    t0 = time.perf_counter()
    summary = train(out / "data", work, preset="tiny", steps=args.steps, seed=args.seed, progress=False,
                    overrides=overrides)
    train_s = time.perf_counter() - t0

    loaded = load_workdir(work)  # flat configs of earlier versions are mapped (LEGACY_DEFAULTS)
    cfg, params, pose_stats, speech_stats = loaded.cfg, loaded.params, loaded.pose_stats, loaded.speech_stats
    clips = [c for c in load_folder(out / "data_heldout", progress=False) if c.audio is not None]
    held = zdata.build(clips, fps=cfg.model.fps, mirror=False, speeds=(1.0,), pose_stats=pose_stats,
                       speech_stats=speech_stats, loudness=cfg.model.loudness)
    score_cfg = cfg.override(**features.fk_fields(clips[0].motion.skeleton))
    rows = {k: [] for k in TERMS}
    mean, std = np.asarray(pose_stats.mean, np.float32), np.asarray(pose_stats.std, np.float32)
    fn = jax.jit(lambda p, b, k: loss_terms(p, b, k, 10 ** 6, cfg=score_cfg, pose_mean=mean, pose_std=std,
                                            deterministic=True))
    for i in range(args.windows // 16):
        b = held.batch(i, seed=1234, batch=16, window=cfg.train.window, style_min=cfg.train.style_window_min,
                       style_max=cfg.train.style_window_max)
        terms = fn(params, b, jax.random.key(i))
        for k in TERMS:
            rows[k].extend(np.asarray(terms[k], np.float64).tolist())
    res = {"variant": args.variant, "seed": args.seed, "steps": args.steps, "overrides": {k: v for k, v in overrides.items()
                                                                      if k not in ("fk_parents", "fk_offsets")},
           "not_in_config": skipped, "train_s": train_s, "final_train_loss": summary["final"].get("loss"),
           "heldout": rows, "heldout_mean": {k: float(np.mean(v)) for k, v in rows.items()}}
    (out / f"{name}.json").write_text(json.dumps(res, indent=1))
    print(json.dumps({k: res[k] for k in ("variant", "train_s", "final_train_loss", "heldout_mean")}))


if __name__ == "__main__":
    main()

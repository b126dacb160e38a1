"""Does the soft swap blend by content or copy by position? Transformer variants on one frozen autoencoder.

    python experiments/tgst_bandai/swap_variants.py AE_WORKDIR AE_STEP TRAIN_DIR EVAL_DIR OUT_DIR \
        [--steps 3000] [--seeds 0] [--variants index-dot,none-dot,index-scaled,none-scaled]

For each variant "<positions>-<similarity>" (transformer.token_positions = index | none, swap_similarity =
dot | scaled) and seed: the autoencoder checkpoint AE_WORKDIR/checkpoints/autoencoder/AE_STEP is copied into
OUT_DIR/<variant>-s<seed>, a transformer is trained on TRAIN_DIR (jaxgest.tgst.trainer.train with the
overrides) and the soft-swap weights of every inter pair of EVAL_DIR are summarised (diagnose.swap_stats:
mean largest weight, effective number of tokens, argmax within +-1 index of the query's own index and its
chance). Clips are padded at the end (edge frames) to a multiple of 256 frames to share compilations; the
rows are cut back to the real content tokens, the style's padding tokens stay among the columns.
Results: OUT_DIR/swap_variants.json and a table on stdout.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import shutil
import sys

import jax
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from diagnose import body_upper_lower, load_params, swap_stats  # noqa: E402

from jaxgest.motion import datasets  # noqa: E402
from jaxgest.tgst import model as tmodel  # noqa: E402
from jaxgest.tgst.evaluate import make_pairs  # noqa: E402
from jaxgest.tgst.trainer import AE_SUBDIR, train  # noqa: E402


def bucket(x, multiple=256):
    """The end replicated up to a multiple of ``multiple`` frames (fewer compilations)."""
    return np.concatenate([x, np.repeat(x[-1:], -len(x) % multiple, axis=0)])


def overrides_of(variant: str) -> dict:
    positions, similarity = variant.split("-")
    return {"transformer.token_positions": positions, "swap_similarity": similarity}


def main(argv) -> int:
    ap = argparse.ArgumentParser()
    for a in ("ae_workdir", "ae_step", "train_dir", "eval_dir", "out_dir"):
        ap.add_argument(a)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--preset", default="fit")
    ap.add_argument("--variants", default="index-dot,none-dot,index-scaled,none-scaled")
    args = ap.parse_args(argv[1:])
    out_dir = pathlib.Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    clips = datasets.load_folder(args.eval_dir, progress=False)
    results = {}
    res_path = out_dir / "swap_variants.json"
    if res_path.exists():
        results = json.loads(res_path.read_text())
    for variant in args.variants.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            name = f"{variant}-s{seed}"
            if name in results:
                continue
            wd = out_dir / name
            src = pathlib.Path(args.ae_workdir) / AE_SUBDIR / args.ae_step
            dst = wd / AE_SUBDIR / args.ae_step
            if not dst.exists():
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copytree(src, dst)
            summary = train(args.train_dir, wd, preset=args.preset, ae_steps=int(args.ae_step),
                            transformer_steps=args.steps, seed=seed, progress=False, log_every=500,
                            ckpt_every=args.steps, overrides=overrides_of(variant))
            cfg, params = load_params(wd)
            held = {c.path: body_upper_lower(c.motion, cfg.fps)[0] for c in clips}
            sw = jax.jit(lambda p, c, s: tmodel.swap_weights(p, c[None], s[None], cfg=cfg)[0])
            stats = []
            for pair in make_pairs(clips, "inter"):
                c, s = held[pair.content.path], held[pair.style.path]
                w = np.asarray(sw(params, bucket(c), bucket(s)))  # padded: rows cut to the real tokens
                stats.append(swap_stats(w[:tmodel.num_tokens(-(-len(c) // 4))]))
            results[name] = {"variant": variant, "seed": seed, "steps": args.steps,
                             "loss": summary["transformer"].get("loss"),
                             "terms": {k: summary["transformer"].get(k) for k in
                                       ("identity", "cyclic", "structure", "appearance")},
                             "num_pairs": len(stats),
                             **{k: float(np.mean([s[k] for s in stats])) for k in stats[0]}}
            res_path.write_text(json.dumps(results, indent=1))
            print(name, json.dumps(results[name]), flush=True)
    print("| variant | seed | max weight | effective tokens | argmax within +-1 | chance | loss |")
    print("|---|---|---|---|---|---|---|")
    for r in results.values():
        print(f"| {r['variant']} | {r['seed']} | {r['max_weight']:.3f} | {r['effective_tokens']:.2f} | "
              f"{r['argmax_within_1']:.3f} | {r['chance_within_1']:.3f} | "
              f"{'-' if r['loss'] is None else format(r['loss'], '.3f')} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

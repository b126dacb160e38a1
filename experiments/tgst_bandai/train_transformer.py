"""A preset's (default `fit`) transformer on a trained autoencoder, with config overrides (e.g. the style data mode).

    python experiments/tgst_bandai/train_transformer.py TRAIN_DIR WORKDIR AE_STEPS TR_STEPS SEED [--ablate TERM] [--preset fit] [key=value ...]

WORKDIR must already hold the autoencoder checkpoint AE_STEPS (copied in: checkpoints/autoencoder/AE_STEPS);
the transformer is trained for TR_STEPS steps with seed SEED (checkpoint at the end). ``key=value`` pairs are
config overrides (Python literals), e.g. ``train.transformer.style_tokens=clip_and_mirror`` (the whole style
clip + its mirror as one token set, as the authors' trainer) or ``train.transformer.style_tokens=window``.
"""
import argparse
import sys

from jaxgest.tgst.trainer import format_summary, train
from overrides import parse_value




if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("train_dir"), ap.add_argument("workdir")
    ap.add_argument("ae_steps", type=int), ap.add_argument("tr_steps", type=int), ap.add_argument("seed", type=int)
    ap.add_argument("--ablate", default=None)
    ap.add_argument("--preset", default="fit")
    ap.add_argument("overrides", nargs="*")
    a = ap.parse_intermixed_args()
    overrides = {k: parse_value(v) for k, v in (o.split("=", 1) for o in a.overrides)}
    print(f"overrides {overrides}, ablate {a.ablate}", flush=True)
    print(format_summary(train(a.train_dir, a.workdir, preset=a.preset, ae_steps=a.ae_steps,
                               transformer_steps=a.tr_steps, seed=a.seed, progress=False, log_every=50,
                               ckpt_every=a.tr_steps, ablate=(a.ablate.split(",") if a.ablate else ()),
                               overrides=overrides)))
    sys.exit(0)

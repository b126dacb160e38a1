"""Does the mirrored half of the autoencoder's data hurt it? The `fit` recipe trained on the original clips only.

    python experiments/tgst_bandai/ae_mirror_check.py TRAIN_DIR WORKDIR STEPS

Trains the autoencoder of the `fit` preset with ``ae_mirror=False`` (same seed, schedule and sampling) for
STEPS steps into WORKDIR; compare with diagnose.py WORKDIR EVAL_DIR OUT.json TRAIN_DIR --no-swap.
"""
import sys

from jaxgest.tgst.train import format_summary, train

if __name__ == "__main__":
    train_dir, workdir, steps = sys.argv[1], sys.argv[2], int(sys.argv[3])
    print(format_summary(train(train_dir, workdir, preset="fit", ae_steps=steps, transformer_steps=0, seed=0,
                               progress=False, log_every=100, ckpt_every=500, overrides={"ae_mirror": False})))

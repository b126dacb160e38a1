"""The `fit` autoencoder trained with each way of mirroring its training clips (same seed, schedule, budget).

    python experiments/tgst_bandai/ae_mirror_runs.py MODE TRAIN_DIR WORKDIR STEPS SEED [key=value ...]

MODE: ``new`` (mirrored clips by :func:`jaxgest.tgst.data.mirror_motion`, the rig's T-pose as the symmetric
reference: the current pipeline), ``old`` (the previous offset-inferred mirror, :mod:`old_mirror`, swapped
into the data pipeline), ``none`` (``ae_mirror=False``: original clips only). The cosine schedule is
shortened to STEPS (``ae_lr_decay_steps=STEPS``) so a short run ends at the schedule's end. Extra
``key=value`` pairs are config overrides (Python literals), e.g.
``autoencoder.encoder_channels=(64,32,32)`` (latent width d_z = 32); ``preset=NAME`` picks another preset
than ``fit`` (e.g. ``preset=fit-pca``).
Evaluate with diagnose.py WORKDIR EVAL_DIR OUT.json TRAIN_DIR --no-swap.
"""
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

from jaxgest.tgst import data as tdata  # noqa: E402
from jaxgest.tgst.trainer import format_summary, train  # noqa: E402
from overrides import parse_value  # noqa: E402




if __name__ == "__main__":
    mode, train_dir, workdir, steps, seed = sys.argv[1:6]
    steps, seed = int(steps), int(seed)
    overrides = {"ae_lr_decay_steps": steps}
    overrides.update({k: parse_value(v) for k, v in (a.split("=", 1) for a in sys.argv[6:])})
    preset = overrides.pop("preset", "fit")
    if mode == "none":
        overrides["ae_mirror"] = False
    elif mode == "old":
        from old_mirror import old_mirror

        tdata.mirror_motion = old_mirror
    elif mode != "new":
        sys.exit(f"ae_mirror_runs.py: unknown MODE {mode!r} (new, old or none)")
    print(f"mode {mode}, overrides {overrides}", flush=True)
    print(format_summary(train(train_dir, workdir, preset=preset, ae_steps=steps, transformer_steps=0, seed=seed,
                               progress=False, log_every=100, ckpt_every=500, overrides=overrides)))

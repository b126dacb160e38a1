"""How the session's shared tiny models (tests/conftest.py) are trained; tests that retrain one for a comparison
(determinism, resume) call the same functions, overriding only what they compare."""

from __future__ import annotations

#: How the shared workdirs are trained (tests that retrain for comparison use the same values).
TINY_SEED = 0
TGST_STEPS = {"ae_steps": 4, "transformer_steps": 4}
ZEGGS_STEPS = 4
CKPT_EVERY = 2


def train_tgst(data, workdir, seed=TINY_SEED, **kw):
    """TGST tiny preset as the shared workdir is trained (keywords override)."""
    from jaxgest.tgst.trainer import train

    args = dict(preset="tiny", seed=seed, progress=False, log_every=1, ckpt_every=CKPT_EVERY, **TGST_STEPS)
    return train(data, workdir, **{**args, **kw})


def train_zeggs(data, workdir, seed=TINY_SEED, **kw):
    """ZeroEGGS tiny preset as the shared workdir is trained (keywords override)."""
    from jaxgest.zeggs.trainer import train

    args = dict(preset="tiny", seed=seed, progress=False, log_every=1, ckpt_every=CKPT_EVERY, steps=ZEGGS_STEPS)
    return train(data, workdir, **{**args, **kw})

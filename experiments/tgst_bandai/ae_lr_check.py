"""Diagnostic (issue 3): TGST autoencoder convergence on all Bandai-Namco clips at two learning rates.

Paper preset, 2,000 Adam steps each (lr 1e-4 as in the paper, and 1e-3); prints loss, upper/lower loss and
mean angular error every 500 steps. Run from the repository root:
python experiments/tgst_bandai/ae_lr_check.py
"""
import dataclasses, time, sys
import jax, jax.numpy as jnp, optax, numpy as np
from jaxgest.tgst import data as tdata
from jaxgest.tgst.config import preset
from jaxgest.tgst.model import init_params
from jaxgest.tgst.steps import create_ae_state, make_ae_train_step
cfg0 = preset("paper")
bd = tdata.load_body_data("../shared/data/bandai-namco-1", cfg0)
cfg = tdata.fit_windows(cfg0, bd)
p0 = init_params(cfg.model, jax.random.key(0))
for lr in (1e-4, 1e-3):
    tx = optax.adam(lr)
    st = create_ae_state(cfg, p0["autoencoder"], tx)
    step = jax.jit(make_ae_train_step(cfg, tx))
    t=time.time()
    for i in range(2000):
        st, m = step(st, tdata.ae_batch(bd, cfg, 0, i), jax.random.key(i))
        if (i+1) % 500 == 0:
            print(lr, i+1, {k: round(float(v),3) for k,v in m.items()}, f"{time.time()-t:.0f}s", flush=True)

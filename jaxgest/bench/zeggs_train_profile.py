"""Where a ZeroEGGS training step spends its time (``small`` preset by default), piece by piece.

``python -m jaxgest.bench.zeggs_train_profile [--preset small] [--repeats 5] [--unroll 1,2,4,8] [--out x.json]``

Times, on one random batch of the preset's shape (:func:`jaxgest.bench.cases.training.zeggs_batch`), each
jit-compiled apart (median of ``repeats`` calls, after a warm-up; compile seconds apart):

* ``step``: the whole training step (forward, losses, backward, RAdam), as ``jaxgest zeggs train`` jits it;
* ``loss``: forward and losses only (no gradient);
* ``generator``: the autoregressive generator's forward alone (the ``nn.scan`` over the window);
* ``grad``: forward + backward without the optimiser update;
* ``step_unroll{k}``: the whole step with the generator's scan unrolled ``k`` frames per loop iteration
  (an experiment: the scan's ``unroll`` is patched in for this process only);
* ``host_batch``: the host-side data pipeline (:meth:`jaxgest.zeggs.data.ZeggsData.batch`), when ``--data``
  is given (a folder of BVH + WAV clips, e.g. ``jaxgest synth --out DIR``); the model config then has that
  rig (FK position terms on, as ``jaxgest zeggs train`` runs) and the batch is a real one;
* ``speech_encoder_grad`` / ``style_encoder_grad`` / ``generator_grad`` / ``recon_terms_grad``: forward +
  backward of each part alone.

Also the loss of a few steps with each unroll (an unrolled scan runs the same operations; its losses must
equal the rolled one's to float rounding). On a shared machine every number stretches with the load:
compare the pieces of one run, and ``cpu_s`` (process CPU per call) with ``wall_s``.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np


@contextlib.contextmanager
def scan_unroll(k: int):
    """Patch the generator's ``nn.scan`` to ``unroll=k`` (this process, inside the block)."""
    import flax.linen as nn

    from jaxgest.zeggs import generator as G

    class _NN:
        def __getattr__(self, name):
            return getattr(nn, name)

        scan = staticmethod(functools.partial(nn.scan, unroll=k))

    old = G.nn
    G.nn = _NN()
    try:
        yield
    finally:
        G.nn = old


def _time(f, args, repeats):
    jax.block_until_ready(f(*args))
    wall, cpu = [], []
    for _ in range(repeats):
        c, t = time.process_time(), time.perf_counter()
        jax.block_until_ready(f(*args))
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return {"wall_s": statistics.median(wall), "min_s": min(wall), "cpu_s": statistics.median(cpu)}


def _compile(fn, args, options=None):
    t = time.perf_counter()
    c = jax.jit(fn, compiler_options=options).lower(*args).compile()
    return c, time.perf_counter() - t


def profile(preset: str = "small", repeats: int = 5, unrolls=(1, 2, 4, 8), loss_steps: int = 3,
            data_dir=None) -> dict:
    """The pieces' times (``PROFILE_PIECES=a,b`` in the environment: only those; ``unrolls=()``: no steps)."""
    from flax.training.train_state import TrainState

    from jaxgest.bench.cases.training import zeggs_batch
    from jaxgest.bench.cases.zeggs import random_params
    from jaxgest.zeggs import steps as ZS
    from jaxgest.zeggs.config import preset as zeggs_config

    out: dict = {"preset": preset, "load_avg_1m": __import__("os").getloadavg()[0], "pieces": {}}
    if data_dir:  # the real configuration (rig, FK position terms) and pipeline of `jaxgest zeggs train`
        from jaxgest.motion.datasets import load_folder
        from jaxgest.zeggs import data as zdata
        from jaxgest.zeggs.trainer import config_for

        clips = [c for c in load_folder(data_dir, progress=False) if c.audio is not None]
        cfg = config_for(preset, clips[0].motion.skeleton)
        m, t = cfg.model, cfg.train
        a = t.speed_augmentation
        data = zdata.build(clips, fps=m.fps, mirror=t.mirror, speeds=(1 - a, 1.0, 1 + a) if a > 0 else (1.0,),
                           progress=False, loudness=m.loudness, input_norm=m.input_norm,
                           speech_method=m.speech_features)

        def batch_fn(i):
            return data.batch(i, seed=0, batch=t.batch_size, window=t.window, style_min=t.style_window_min,
                              style_max=t.style_window_max, sampling=t.style_sampling)

        batch_fn(0)
        times = []
        for i in range(1, 21):
            c = time.perf_counter()
            batch_fn(i)
            times.append(time.perf_counter() - c)
        out["pieces"]["host_batch"] = {"wall_s": statistics.median(times), "min_s": min(times)}
        print("host_batch", out["pieces"]["host_batch"], flush=True)
        batch = jax.tree_util.tree_map(jnp.asarray, batch_fn(0))
        stats = ZS.pose_stats(m, data.pose_stats.mean, data.pose_stats.std)
    else:
        cfg = zeggs_config(preset)
        m, t = cfg.model, cfg.train
        batch = zeggs_batch(m, t.batch_size, t.window, t.style_window_max)
        stats = ZS.pose_stats(m)
    tx = ZS.make_optimizer(cfg)
    params = random_params(m)
    key = jax.random.key(0)
    opts = t.compiler_options
    out.update(batch=t.batch_size, window=t.window, compiler_options=opts, fk=bool(m.fk_parents))

    def state0():
        return TrainState.create(apply_fn=None, params=params, tx=tx)

    def loss_fn(p, b, k):
        terms = ZS.loss_terms(p, b, k, jnp.asarray(0), cfg=cfg, pose_mean=stats["mean"], pose_std=stats["std"])
        return jnp.mean(terms["loss"])

    def generator(p, b):
        B = b["pose"].shape[0]
        style = jnp.zeros((B, m.style_embedding), jnp.float32)
        from jaxgest.zeggs.generator import Generator

        speech = jnp.zeros((B, b["speech"].shape[1], m.speech_embedding), jnp.float32)
        return Generator(m).apply({"params": p["generator"]}, b["pose"][:, 0], b["root_position"][:, 0],
                                  b["root_rotation"][:, 0], b["facing"], speech, style)

    from jaxgest.zeggs import losses as L
    from jaxgest.zeggs.model import ZeggsModel

    model = ZeggsModel(m)

    def speech_enc(p, b, k):  # forward + backward of the speech encoder (dropout on), as in training
        return jnp.sum(model.apply({"params": p}, b["speech"], deterministic=False,
                                   method=ZeggsModel.encode_speech, rngs={"dropout": k}))

    def style_enc(p, b, k):
        mu, logvar = model.apply({"params": p}, b["style"], b["style_mask"], deterministic=False,
                                 method=ZeggsModel.encode_style, rngs={"dropout": k})
        return jnp.sum(mu) + jnp.sum(logvar)

    def recon(pose, b):  # eq. 2's terms on a predicted pose (gradient w.r.t. the prediction)
        terms = L.reconstruction_terms(pose, b["root_position"], b["root_rotation"], b["pose"],
                                       b["root_position"], b["root_rotation"], cfg=m)
        return jnp.mean(L.total_loss(terms, jnp.zeros(pose.shape[:1]), 0.0, cfg=t))

    pred = batch["pose"] + 0.1
    pieces = {
        "loss": (loss_fn, (params, batch, key)),
        "grad": (jax.grad(loss_fn), (params, batch, key)),
        "generator": (generator, (params, batch)),
        "generator_grad": (jax.grad(lambda p, b: jnp.sum(generator(p, b)["pose"])), (params, batch)),
        "speech_encoder_grad": (jax.grad(speech_enc), (params, batch, key)),
        "style_encoder_grad": (jax.grad(style_enc), (params, batch, key)),
        "recon_terms_grad": (jax.grad(recon), (pred, batch)),
    }
    only = __import__("os").environ.get("PROFILE_PIECES")
    if only:
        pieces = {k: v for k, v in pieces.items() if k in only.split(",")}
    for name, (fn, args) in pieces.items():
        c, comp = _compile(fn, args, opts)
        out["pieces"][name] = dict(_time(c, args, repeats), compile_s=comp)
        print(name, out["pieces"][name], flush=True)
    losses = {}
    for k in unrolls:
        jax.clear_caches()  # a fresh trace: the patched scan must be traced again
        with scan_unroll(k):
            c, comp = _compile(ZS.make_train_step(cfg), (state0(), batch, key, stats), opts)
        name = "step" if k == 1 else f"step_unroll{k}"
        out["pieces"][name] = dict(_time(c, (state0(), batch, key, stats), repeats), compile_s=comp)
        print(name, out["pieces"][name], flush=True)
        s, ls = state0(), []
        for _ in range(loss_steps):
            s, met = c(s, batch, key, stats)
            ls.append(float(met["loss"]))
        losses[k] = ls
    out["losses_by_unroll"] = {str(k): v for k, v in losses.items()}
    if not unrolls:
        return out
    ref = np.asarray(losses[unrolls[0]])
    out["max_rel_loss_diff_vs_rolled"] = {str(k): float(np.max(np.abs(np.asarray(v) - ref) / np.abs(ref)))
                                          for k, v in losses.items()}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jaxgest.bench.zeggs_train_profile", description=__doc__.split("\n")[0])
    p.add_argument("--preset", default="small")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--unroll", default="1,2,4,8", help="comma-separated scan unroll factors (1 = as shipped)")
    p.add_argument("--out", default=None, help="write the JSON here")
    p.add_argument("--data", default=None, help="a BVH + WAV folder (e.g. `jaxgest synth --out DIR`): its rig and "
                                                  "batches, and the host data pipeline timed")
    a = p.parse_args(argv)
    res = profile(a.preset, a.repeats, tuple(int(x) for x in a.unroll.split(",") if x), data_dir=a.data)
    text = json.dumps(res, indent=2)
    if a.out:  # a stamped results file (commit, version, config, command)
        from jaxgest.runtime.provenance import write_results

        write_results(a.out, res, {"preset": a.preset, "repeats": a.repeats, "unroll": a.unroll, "data": a.data}, ["python", "-m", __spec__.name] + list(sys.argv[1:] if argv is None else argv))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

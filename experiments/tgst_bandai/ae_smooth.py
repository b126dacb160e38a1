"""Smooth linear paths for the autoencoder: small in-process runs scored on angle error AND round-trip speed.

    python experiments/tgst_bandai/ae_smooth.py NAME STEPS [key=value ...]   # -> out/results/ae_smooth/NAME.json
    python experiments/tgst_bandai/ae_smooth.py table NAME [NAME ...]        # markdown rows of finished runs

Data: out/ae_cache.npz (``ae_cause.py cache``: training clips original + T-pose mirror at the model rate, the
30 held-out clips); the held-out BVH files (out/data_eval) give the skeletons of the round-trip motions. A run
starts from preset ``fit-pca`` (``preset=NAME`` for another), applies ``key=value`` config overrides (dotted
paths of ``jaxgest.tgst.trainer.apply_overrides``, e.g. ``autoencoder.linear_context=1``,
``train.autoencoder.init_velocity_weight=64.0``), shortens the cosine schedule to STEPS, initialises the linear path
(:func:`jaxgest.tgst.autoencoder.init_linear_path` on the original + mirrored training clips, with
``init_velocity_weight``) and trains STEPS Adam steps with the training step of ``jaxgest tgst train``
(:func:`jaxgest.tgst.steps.make_ae_train_step`: the paper's loss plus the optional velocity term); STEPS=0
scores the closed-form start. ``seed=S`` (default 0). Decompositions of the round trip (the angles are the
model's): ``truth=upper`` / ``truth=lower`` writes the input's upper / lower body instead of the decoded one;
``contact=content`` writes the root as the content's own (no per-frame floor contact from the decoded feet).

Scores on the held-out clips: mean geodesic angle (upper body, per clip and joint) beside PCA-16 fitted on the
original training clips and on original + mirrored ones (paired per clip: mean +- SE); first frame vs
interior; exp-map change by frame phase (``ae_jitter.phase_speed``); and the round trip as motions
(``diagnose.roundtrip``: world arm speed ratios overall / frames 0-5, per-joint interior ratios, round-trip
style error under the world and the authors' protocols).
"""
from __future__ import annotations

import json
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from ae_cause import load_cache  # noqa: E402
from ae_jitter import phase_speed  # noqa: E402
from overrides import parse_value  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
RES = HERE / "out" / "results" / "ae_smooth"


def paired(a, b) -> dict:
    d = np.asarray(a) - np.asarray(b)
    return {"mean": float(d.mean()), "se": float(d.std(ddof=1) / np.sqrt(len(d))), "lower": int((d < 0).sum()),
            "n": len(d)}


def reconstruct_all(params, mcfg, clips):
    from jaxgest.tgst import model as tmodel

    rec = jax.jit(lambda p, u: tmodel.reconstruct(p, u, cfg=mcfg))
    outs = []
    for u, _ in clips:  # the end replicated to a multiple of 128 frames (as diagnose.py): few compilations
        f = len(u)
        up = np.concatenate([u, np.repeat(u[-1:], -f % 128, axis=0)])
        a, b = rec(params, up[None])
        outs.append((np.asarray(a)[0, :f], np.asarray(b)[0, :f]))
    return outs


def run(name, steps, args):
    import optax

    from diagnose import roundtrip
    from jaxgest.motion import datasets
    from jaxgest.tgst import autoencoder as ae_mod
    from jaxgest.tgst import baselines
    from jaxgest.tgst import data as tdata
    from jaxgest.tgst import model as tmodel
    from jaxgest.tgst.autoencoder import angular_error_rad
    from jaxgest.tgst.config import preset
    from jaxgest.tgst.steps import make_ae_train_step
    from jaxgest.tgst.trainer import ae_learning_rate, apply_overrides

    seed = int(args.pop("seed", 0))
    base = args.pop("preset", "fit-pca")
    truth = args.pop("truth", None)  # "upper" | "lower": that part of the round trip replaced by the input
    contact = args.pop("contact", "frame")  # "content": the content's own root height (no per-frame contact)
    data, held, _ = load_cache()
    cfg = apply_overrides(preset(base), {"ae_lr_decay_steps": max(steps, 2), **args})
    cfg = tdata.fit_windows(cfg, data)
    mcfg = cfg.model
    params = tmodel.init_params(mcfg, jax.random.key(seed))["autoencoder"]
    if mcfg.autoencoder.standardize:
        params = dict(params, **{k: jnp.asarray(v) for k, v in tdata.channel_stats(data).items()})
    t0 = time.perf_counter()
    if mcfg.autoencoder.linear_path and cfg.train.autoencoder.pca_init:
        params = ae_mod.init_linear_path(params, mcfg.autoencoder, data.upper + data.mirrored_upper,
                                         data.lower + data.mirrored_lower,
                                         velocity_weight=cfg.train.autoencoder.init_velocity_weight)
    init_s = time.perf_counter() - t0
    curve = []
    if steps:
        from flax.training.train_state import TrainState

        tx = optax.adam(ae_learning_rate(cfg))
        state = TrainState.create(apply_fn=None, params=params, tx=tx)
        step = jax.jit(make_ae_train_step(cfg, tx))
        for i in range(steps):
            state, m = step(state, tdata.ae_batch(data, cfg, seed, i), jax.random.key(i))
            if i % 100 == 0 or i == steps - 1:
                curve.append((i, float(m["loss"]), float(m["velocity_loss"])))
                print(f"{name} step {i} loss {curve[-1][1]:.4f} vel {curve[-1][2]:.4f} "
                      f"{time.perf_counter() - t0:.0f}s", flush=True)
        params = state.params
    train_s = time.perf_counter() - t0

    outs = reconstruct_all(params, mcfg, held)
    ae = [baselines.per_joint_angle_deg(u_hat, u) for (u_hat, _), (u, _) in zip(outs, held)]
    first, interior = [], []
    for (u_hat, _), (u, _) in zip(outs, held):
        err = np.degrees(np.asarray(angular_error_rad(u_hat, u)))
        first.append(err[0].mean())
        interior.append(err[16:-16].mean() if len(err) > 40 else err.mean())
    pca = baselines.block_pca_fit(data.upper, components=16, frames=4)
    pca_mix = baselines.block_pca_fit(data.upper + data.mirrored_upper, components=16, frames=4)
    base_pc = {k: [baselines.per_joint_angle_deg(baselines.block_pca_reconstruct(p, u), u).mean() for u, _ in held]
               for k, p in (("pca16", pca), ("pca16_mix", pca_mix))}
    ae_pc = np.mean(ae, axis=1)
    long = [i for i, (u, _) in enumerate(held) if len(u) > 40]
    clips = datasets.load_folder(HERE / "out" / "data_eval", progress=False)
    if truth == "upper":
        outs = [(u, l_hat) for (_, l_hat), (u, _) in zip(outs, held)]
    elif truth == "lower":
        outs = [(u_hat, l) for (u_hat, _), (_, l) in zip(outs, held)]
    elif truth is not None:
        sys.exit(f"ae_smooth.py: truth=upper|lower, got {truth!r}")
    if contact == "content":  # root written as the content's (TGSTModel.to_motion without the floor contact)
        from jaxgest.tgst import api

        api.content_floor_contact = lambda result, content, **kw: result
    rt = roundtrip(mcfg, clips, outs)
    from jaxgest.motion import body

    extra = {k: v for k, v in (("truth", truth), ("contact", contact)) if v not in (None, "frame")}
    res = {"name": name, "steps": steps, "args": {**args, "seed": seed, "preset": base, **extra}, "init_s": init_s,
           "train_s": train_s, "curve": curve,
           "angle_deg": float(ae_pc.mean()), "per_joint": dict(zip(body.UPPER, np.mean(ae, 0).round(2).tolist())),
           "per_clip": ae_pc.round(4).tolist(), "pca16_deg": float(np.mean(base_pc["pca16"])),
           "pca16_mix_deg": float(np.mean(base_pc["pca16_mix"])),
           "vs_pca16": paired(ae_pc, base_pc["pca16"]), "vs_pca16_mix": paired(ae_pc, base_pc["pca16_mix"]),
           "first_deg": float(np.mean(first)), "interior_deg": float(np.mean(interior)),
           "phase_speed": phase_speed([outs[i][0] for i in long], [held[i][0] for i in long]),
           "roundtrip": {k: v for k, v in rt.items() if k != "clips"}}
    RES.mkdir(parents=True, exist_ok=True)
    (RES / f"{name}.json").write_text(json.dumps(res, indent=1))
    print(json.dumps({k: v for k, v in res.items() if k not in ("per_clip", "curve")}))
    return params, cfg


def table(names):
    print("| run | steps | overrides | held-out (deg) | - PCA-16 (paired) | - PCA-16 mirrored (paired) | first / interior "
          "| exp-map change by phase 0/1/2/3 | arm speed ratio overall / 0-5 | per-joint interior ratio | "
          "round-trip style world / authors (m/s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n in names:
        r = json.loads((RES / f"{n}.json").read_text())
        a = {k: v for k, v in r["args"].items() if k not in ("preset",)}
        var = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in a.items())
        rt, p = r["roundtrip"], r["phase_speed"]["by_phase"]
        jr = list(rt["joint_interior_ratio"].values())
        print(f"| {n} | {r['steps']} | {var} | {r['angle_deg']:.2f} | {r['vs_pca16']['mean']:+.2f} +- "
              f"{r['vs_pca16']['se']:.2f} ({r['vs_pca16']['lower']}/{r['vs_pca16']['n']}) | "
              f"{r['vs_pca16_mix']['mean']:+.2f} +- {r['vs_pca16_mix']['se']:.2f} | {r['first_deg']:.1f} / "
              f"{r['interior_deg']:.1f} | {' / '.join(f'{x:.2f}' for x in p)} | {rt['speed_ratio']:.2f} / "
              f"{rt['speed_ratio_0_5']:.2f} | {min(jr):.2f}-{max(jr):.2f} | {rt['style_world']:.2f} / "
              f"{rt['style_authors']:.2f} |")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "table":
        table(sys.argv[2:])
    elif len(sys.argv) >= 3:
        run(sys.argv[1], int(sys.argv[2]), {k: parse_value(v) for k, v in (a.split("=", 1) for a in sys.argv[3:])})
    else:
        sys.exit("usage: ae_smooth.py NAME STEPS [key=value ...] | ae_smooth.py table NAME [NAME ...]")

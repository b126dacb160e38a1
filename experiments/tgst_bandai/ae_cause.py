"""Why the `fit` autoencoder under-fits: small, fast in-process runs on the held-out split.

    python experiments/tgst_bandai/ae_cause.py cache TRAIN_DIR EVAL_DIR        # once: out/ae_cache.npz
    python experiments/tgst_bandai/ae_cause.py run NAME STEPS [key=value ...]   # one variant -> out/results/ae_cause/NAME.json
    python experiments/tgst_bandai/ae_cause.py table NAME [NAME ...]            # markdown table of finished runs

The cache holds the body exp-maps of the training clips (original + T-pose mirror, content labels) and of
the held-out clips, at the model rate, so each run starts training in seconds. A run trains the autoencoder
of the `fit` preset (config overrides as ``key=value``: dotted paths of ``jaxgest.tgst.trainer.apply_overrides``,
e.g. ``autoencoder.latent_activation=False``) with the preset's own step, batches and schedule shortened to
STEPS, and reports: loss curve, per-layer gradient norms at the end, the fraction of latent channels that
are (nearly) constant, and the mean geodesic angle (upper body, degrees) of
``jaxgest.tgst.model.reconstruct`` on (a) the 30 held-out clips, (b) the 15 training clips of the gesture
content ``bye`` -- beside PCA-16 (fitted on the original training clips) on the same clips.

Special keys (not config fields):
  ``act=identity``       every GELU replaced by the identity (a linear autoencoder of the same shapes);
  ``loss=squared``       squared exp-map differences instead of the authors' unsquared L2 norm;
  ``loss=upper``         the upper-body term only (the lower decoder gets no gradient);
  ``subset=CONTENT``     train on the clips of one training content only (overfit test);
  ``clips=N``            train on the first N clips of that subset only;
  ``seed=S``             seed (default 0).
"""
from __future__ import annotations

import json
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax
from overrides import parse_value

HERE = pathlib.Path(__file__).resolve().parent
OUT = HERE / "out"
CACHE = OUT / "ae_cache.npz"


def cache(train_dir, eval_dir):
    from jaxgest.motion import datasets
    from jaxgest.tgst import data as tdata
    from jaxgest.tgst.config import preset

    cfg = preset("fit")
    tr = tdata.load_body_data(train_dir, cfg)
    ev = datasets.load_folder(eval_dir)
    z = {"train_names": np.array([pathlib.Path(n).name for n in tr.names]), "train_contents": np.array(tr.contents),
         "eval_names": np.array([c.path.name for c in ev])}
    for i in range(len(tr.names)):
        z[f"tu{i}"], z[f"tl{i}"], z[f"mu{i}"], z[f"ml{i}"] = (tr.upper[i], tr.lower[i], tr.mirrored_upper[i],
                                                              tr.mirrored_lower[i])
    for i, c in enumerate(ev):
        z[f"eu{i}"], z[f"el{i}"] = tdata.motion_to_arrays(c.motion, cfg.model.fps)
    np.savez(CACHE, **z)
    print(f"cached {len(tr.names)} training and {len(ev)} held-out clips -> {CACHE}")


def load_cache():
    from jaxgest.tgst.data import BodyData

    z = np.load(CACHE)
    n, m = len(z["train_names"]), len(z["eval_names"])
    data = BodyData([z[f"tu{i}"] for i in range(n)], [z[f"tl{i}"] for i in range(n)],
                    [z[f"mu{i}"] for i in range(n)], [z[f"ml{i}"] for i in range(n)],
                    list(z["train_names"]), 60.0, list(z["train_contents"]))
    held = [(z[f"eu{i}"], z[f"el{i}"]) for i in range(m)]
    return data, held, list(z["eval_names"])


def subset(data, keep):
    from jaxgest.tgst.data import BodyData

    return BodyData(*[[getattr(data, a)[i] for i in keep] for a in ("upper", "lower", "mirrored_upper",
                                                                   "mirrored_lower", "names")],
                    data.fps, [data.contents[i] for i in keep])




def pca_angles(data, clips, components=16):
    from jaxgest.tgst import baselines

    pca = baselines.block_pca_fit(data.upper, components=components, frames=4)
    return [baselines.per_joint_angle_deg(baselines.block_pca_reconstruct(pca, u), u) for u, _ in clips]


def ae_angles(params, cfg, clips):
    """Per-clip per-joint angles of the round trip; all clips in one batch (end-replicated to the longest)."""
    from jaxgest.tgst import baselines
    from jaxgest.tgst import model as tmodel

    fmax = -(-max(len(u) for u, _ in clips) // 128) * 128
    batch = np.stack([np.concatenate([u, np.repeat(u[-1:], fmax - len(u), axis=0)]) for u, _ in clips])
    rec = np.asarray(jax.jit(lambda p, u: tmodel.reconstruct(p, u, cfg=cfg)[0])(params, batch))
    out, num, den = [], 0.0, 0.0
    for (u, _), uh in zip(clips, rec):
        uh = uh[:len(u)]
        out.append(baselines.per_joint_angle_deg(uh, u))
        # exp-map channel speed, output / input, interior frames: the jitter of the round trip
        num += np.abs(np.diff(uh[6:-6], axis=0)).sum()
        den += np.abs(np.diff(u[6:-6], axis=0)).sum()
    return out, num / den


def run(name, steps, args):
    from jaxgest.tgst import data as tdata
    from jaxgest.tgst import losses
    from jaxgest.tgst.autoencoder import expmap_reconstruction_loss
    from jaxgest.tgst import model as tmodel
    from jaxgest.tgst.config import preset
    from jaxgest.tgst.trainer import ae_learning_rate, apply_overrides

    special = {k: v for k, v in args.items() if k in ("act", "loss", "subset", "clips", "seed")}
    overrides = {k: v for k, v in args.items() if k not in special}
    seed = int(special.get("seed", 0))
    if special.get("act") == "identity":
        import flax.linen as nn

        nn.gelu = lambda x, approximate=False: x  # the autoencoder module calls nn.gelu at trace time
    data, held, _ = load_cache()
    bye = [i for i, c in enumerate(data.contents) if c == "bye"]
    bye_clips = [(data.upper[i], data.lower[i]) for i in bye]
    train_data = data
    if "subset" in special:
        keep = [i for i, c in enumerate(data.contents) if c == special["subset"]]
        keep = keep[:int(special.get("clips", len(keep)))]
        train_data = subset(data, keep)
    cfg = apply_overrides(preset("fit"), {"ae_lr_decay_steps": steps, **overrides})
    cfg = tdata.fit_windows(cfg, train_data if "subset" not in special else data)
    if "subset" in special:  # short clips: windows no longer than the subset's shortest clip
        import dataclasses

        w = int(min(cfg.train.autoencoder.window, train_data.lengths.min() // 16 * 16))
        cfg = dataclasses.replace(cfg, train=dataclasses.replace(
            cfg.train, autoencoder=dataclasses.replace(cfg.train.autoencoder, window=w)))
    mcfg = cfg.model
    params = tmodel.init_params(mcfg, jax.random.key(seed))["autoencoder"]
    if mcfg.autoencoder.standardize:
        params = dict(params, **{k: jnp.asarray(v) for k, v in tdata.channel_stats(train_data).items()})
    from jaxgest.tgst import autoencoder as ae_mod

    if hasattr(ae_mod, "init_linear_path") and mcfg.autoencoder.linear_path:
        params = ae_mod.init_linear_path(params, mcfg.autoencoder, train_data.upper + train_data.mirrored_upper,
                                         train_data.lower + train_data.mirrored_lower)
    tx = optax.adam(ae_learning_rate(cfg))
    opt = tx.init(params)
    mode = special.get("loss", "l2")

    def loss_fn(p, batch):
        if mode == "l2":
            t = losses.ae_loss_terms(p, batch, cfg=mcfg)
            return jnp.mean(t["loss"]), t
        up_hat, lo_hat = tmodel.reconstruct(p, batch["upper"], cfg=mcfg)
        if mode == "squared":
            pred = jnp.concatenate([up_hat, lo_hat], -1)
            tgt = jnp.concatenate([batch["upper"], batch["lower"]], -1)
            loss = jnp.mean((pred - tgt) ** 2) * 3
        elif mode == "upper":
            loss = jnp.mean(expmap_reconstruction_loss(up_hat, batch["upper"]))
        else:
            raise SystemExit(f"unknown loss {mode}")
        return loss, {"loss": loss}

    @jax.jit
    def step(p, o, batch):
        (l, t), g = jax.value_and_grad(loss_fn, has_aux=True)(p, batch)
        u, o = tx.update(g, o, p)
        return optax.apply_updates(p, u), o, l, g

    curve, t0 = [], time.perf_counter()
    for i in range(steps):
        batch = tdata.ae_batch(train_data, cfg, seed, i)
        params, opt, l, g = step(params, opt, batch)
        if i % 100 == 0 or i == steps - 1:
            curve.append((i, float(l)))
            print(f"{name} step {i} loss {float(l):.4f} {time.perf_counter() - t0:.0f}s", flush=True)
    wall = time.perf_counter() - t0
    gn = {"/".join(str(getattr(k, "key", k)) for k in path): float(jnp.linalg.norm(v))
          for path, v in jax.tree_util.tree_leaves_with_path(g)}
    # latent usage on held-out clips: per-channel std over frames / mean |z|
    fmax = -(-max(len(u) for u, _ in held) // 128) * 128
    padded = np.stack([np.concatenate([u, np.repeat(u[-1:], fmax - len(u), axis=0)]) for u, _ in held])
    zb = np.asarray(jax.jit(lambda p, u: tmodel.encode_clip(p, u, cfg=mcfg))(params, padded))
    zs = np.concatenate([zb[i, slice(*tmodel.clip_latent_range(len(u), cfg=mcfg))] for i, (u, _) in enumerate(held)])
    ae_h, sp_h = ae_angles(params, mcfg, held)
    ae_b, sp_b = ae_angles(params, mcfg, bye_clips)
    res = {"name": name, "steps": steps, "args": args, "wall_s": wall, "curve": curve, "grad_norms": gn,
           "latent_std": zs.std(0).round(4).tolist(), "latent_dead_frac": float((zs.std(0) < 0.05 * zs.std(0).max()).mean()),
           "heldout_deg": float(np.mean(ae_h)), "heldout_per_joint": np.mean(ae_h, 0).round(2).tolist(),
           "heldout_per_clip": np.mean(ae_h, 1).round(3).tolist(),
           "bye_train_deg": float(np.mean(ae_b)), "channel_speed_ratio_heldout": float(sp_h),
           "channel_speed_ratio_bye": float(sp_b)}
    if "subset" in special:
        sub_clips = [(u, l) for u, l in zip(train_data.upper, train_data.lower)]
        a, _ = ae_angles(params, mcfg, sub_clips)
        res["subset_deg"] = float(np.mean(a))
        res["subset_pca16_deg"] = float(np.mean(pca_angles(train_data, sub_clips)))
    pca_file = OUT / "results" / "ae_cause" / "pca16.json"
    if not pca_file.exists():
        pca_file.parent.mkdir(parents=True, exist_ok=True)
        ph, pb = pca_angles(data, held), pca_angles(data, bye_clips)
        pca_file.write_text(json.dumps({"heldout_deg": float(np.mean(ph)), "heldout_per_clip": np.mean(ph, 1).tolist(),
                                        "heldout_per_joint": np.mean(ph, 0).round(2).tolist(),
                                        "bye_train_deg": float(np.mean(pb))}))
    res["pca16"] = json.loads(pca_file.read_text())
    res["pca16"].pop("heldout_per_clip")
    (OUT / "results" / "ae_cause" / f"{name}.json").write_text(json.dumps(res, indent=1))
    print(json.dumps({k: v for k, v in res.items() if k not in ("grad_norms", "heldout_per_clip")}))
    return params, cfg


if __name__ == "__main__":
    if sys.argv[1] == "cache":
        cache(sys.argv[2], sys.argv[3])
    elif sys.argv[1] == "run":
        run(sys.argv[2], int(sys.argv[3]), {k: parse_value(v) for k, v in (a.split("=", 1) for a in sys.argv[4:])})
    elif sys.argv[1] != "table":
        sys.exit("ae_cause.py: cache | run | table")


def table(names):
    """Markdown rows of finished runs: python ae_cause.py table NAME [NAME ...]."""
    d = OUT / "results" / "ae_cause"
    p = json.loads((d / "pca16.json").read_text())
    print("| run | steps | variant | held-out (deg) | `bye` training clips (deg) | exp-map speed out/in, held-out | "
          "latent channels ~constant | final loss |")
    print("|---|---|---|---|---|---|---|---|")
    for n in names:
        r = json.loads((d / f"{n}.json").read_text())
        var = ", ".join(f"{k}={v}" for k, v in r["args"].items()) or "`fit` as is"
        print(f"| {n} | {r['steps']} | {var} | {r['heldout_deg']:.2f} | {r['bye_train_deg']:.2f} | "
              f"{r['channel_speed_ratio_heldout']:.2f} | {r['latent_dead_frac']:.2f} | {r['curve'][-1][1]:.3f} |")
    print(f"| PCA-16 (original training clips) | - | - | {p['heldout_deg']:.2f} | {p['bye_train_deg']:.2f} | | | |")


if __name__ == "__main__" and sys.argv[1] == "table":
    table(sys.argv[2:])

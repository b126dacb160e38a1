"""Why the ZeroEGGS rollout is over-damped: isolating measurements on a trained model (no training).

All errors and variances are in the generator's *input* units: per-channel mean, one std per feature group
(``(x - mean_c) / std_group``, :func:`jaxgest.zeggs.generator.input_scale`), so near-constant channels do
not dominate. Three parts:

1. **Has the model learnt more than the mean?** On training windows drawn as in training (``T`` = the
   config's window, style window apart from the target), the model's free-running prediction against
   predictors that need no model: the mean pose (0 in these units), frame 0 held, and the previous *true*
   frame (a one-step oracle the free-running model cannot use). Mean absolute error per feature group and
   the weighted training reconstruction loss (eq. 2), and the model's error by frame index.
2. **Does motion decay after the training horizon?** On the test clips of ``evaluate`` (10 s each), the
   temporal std of the generated features per window of frames (1-63, 64-127, 128-255, 256-end) divided by
   the real clip's, for the inference initial state (the style example's first frame, as ``generate``) and
   for the clip's own true first frame, the style embedding as ``evaluate`` draws it.
3. **Is the rendering path right?** The predicted velocity / position channels against the same features
   re-extracted from the rendered motion (``generate``'s output): a damped rendering would show there.

Usage: python experiments/zeggs_synthetic/damping_diagnostic.py --workdir W --data D --json OUT.json
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

GROUPS = ("local_positions", "local_rotations", "local_velocities", "local_angular_velocities",
          "root_velocity", "root_angular_velocity")
BINS = ((1, 64), (64, 128), (128, 256), (256, None))


def group_mae(pred: np.ndarray, target: np.ndarray, layout) -> dict:
    """Mean absolute error per feature group over frames 1.. (frame 0 is given), ``(B, T, P)`` arrays."""
    d = np.abs(pred[:, 1:] - target[:, 1:])
    out = {g: float(d[..., getattr(layout, g)].mean()) for g in GROUPS}
    out["all"] = float(d.mean())
    return out


def _rollout_root(pose, mean, std, cfg):
    """Root positions / rotations integrated from normalised (per channel) poses ``(B, T, P)`` (JAX)."""
    import jax
    import jax.numpy as jnp

    from jaxgest.zeggs.generator import update_character_state

    B = pose.shape[0]
    p0 = jnp.zeros((B, 3), jnp.float32)
    q0 = jnp.zeros((B, 4), jnp.float32).at[:, 0].set(1.0)

    def f(carry, y):
        p, q = update_character_state(y, carry[0], carry[1], cfg=cfg, pose_mean=mean, pose_std=std)
        return (p, q), (p, q)

    _, (ps, qs) = jax.lax.scan(f, (p0, q0), jnp.swapaxes(pose[:, 1:], 0, 1))
    return (jnp.concatenate([p0[:, None], jnp.swapaxes(ps, 0, 1)], 1),
            jnp.concatenate([q0[:, None], jnp.swapaxes(qs, 0, 1)], 1))


def part_loss(model, clips, *, batches: int, seed: int) -> dict:
    import jax
    import jax.numpy as jnp

    from jaxgest.zeggs import data as zdata
    from jaxgest.zeggs import losses
    from jaxgest.zeggs.model import ZeggsModel

    cfg = model.cfg
    m, t = cfg.model, cfg.train
    zd = zdata.build(clips, fps=m.fps, mirror=False, speeds=(1.0,), pose_stats=model.pose_stats,
                     speech_stats=model.speech_stats, loudness=m.loudness, input_norm=m.input_norm)
    mean, std, scale = model.pose_mean, model.pose_std, np.asarray(model.input_scale)
    net = ZeggsModel(m)

    @jax.jit
    def run(params, batch, zero_style):
        style = batch["style"] * scale[None, None]
        s = net.apply({"params": params}, batch["speech"], method=ZeggsModel.encode_speech)
        mu, _ = net.apply({"params": params}, style, batch["style_mask"], method=ZeggsModel.encode_style)
        e = jnp.where(zero_style, jnp.zeros_like(mu), mu)
        out = net.apply({"params": params}, s, e, batch["pose"][:, 0], batch["root_position"][:, 0],
                        batch["root_rotation"][:, 0], batch["facing"], mean, std, method=ZeggsModel.generate)
        return out["pose"], out["root_position"], out["root_rotation"]

    @jax.jit
    def recon(pose, rp, rq, batch):
        sd, mn = std[None, None], mean[None, None]
        terms = losses.reconstruction_terms(pose * sd + mn, rp, rq, batch["pose"] * sd + mn,
                                            batch["root_position"], batch["root_rotation"], cfg=m)
        return losses.total_loss(terms, jnp.zeros(pose.shape[0]), jnp.zeros(()), cfg=t)

    names = ("model", "model_e0", "mean_pose", "hold_frame0", "previous_true_frame")
    maes = {k: [] for k in names}
    rec = {k: [] for k in names}
    by_frame = {k: [] for k in ("model", "mean_pose")}
    std_ratio = {"model": [], "model_e0": []}
    quarter = {"model": [], "model_e0": []}
    for b in range(batches):
        batch = zd.batch(10_000 + b, seed=seed, batch=t.batch_size, window=t.window, style_min=t.style_window_min,
                         style_max=t.style_window_max, sampling=t.style_sampling)
        jb = {k: jnp.asarray(v) for k, v in batch.items()}
        y = batch["pose"]
        preds = {}
        for k, z in (("model", False), ("model_e0", True)):
            pose, rp, rq = run(model.params, jb, z)
            preds[k] = (np.asarray(pose), rp, rq)
        const = {"mean_pose": np.concatenate([y[:, :1], np.zeros_like(y[:, 1:])], 1),
                 "hold_frame0": np.repeat(y[:, :1], y.shape[1], 1),
                 "previous_true_frame": np.concatenate([y[:, :1], y[:, :-1]], 1)}
        for k, pose in const.items():
            rp, rq = _rollout_root(jnp.asarray(pose), mean, std, m)
            preds[k] = (pose, rp, rq)
        for k, (pose, rp, rq) in preds.items():
            maes[k].append(group_mae(pose * scale, y * scale, m.layout))
            rec[k].append(np.asarray(recon(jnp.asarray(pose), rp, rq, jb)))
        for k in by_frame:
            by_frame[k].append(np.abs(preds[k][0] - y)[:, 1:].mean(axis=(0, 2)))
        for k in ("model", "model_e0"):  # temporal std within each window, generated / target, per group
            g, r = preds[k][0][:, 1:] * scale, y[:, 1:] * scale
            std_ratio[k].append({grp: float(g[..., getattr(m.layout, grp)].std(1).mean()
                                            / max(r[..., getattr(m.layout, grp)].std(1).mean(), 1e-12))
                                 for grp in GROUPS})
            q = max(1, g.shape[1] // 4)  # by quarter of the window: does the window's initial motion die out?
            vel = m.layout.local_velocities
            quarter[k].append([float(g[:, i * q:(i + 1) * q, vel].std(1).mean()
                                     / max(r[:, i * q:(i + 1) * q, vel].std(1).mean(), 1e-12)) for i in range(4)])
    out = {"windows": batches * t.batch_size, "window": t.window, "sampling": t.style_sampling,
           "mae_group_units": {k: {g: float(np.mean([d[g] for d in v])) for g in v[0]} for k, v in maes.items()},
           "reconstruction_loss": {k: float(np.mean(np.concatenate(v))) for k, v in rec.items()}}
    r = {k: np.concatenate(v) for k, v in rec.items()}
    out["reconstruction_minus_model"] = {
        k: {"mean": float((r[k] - r["model"]).mean()),
            "standard_error": float((r[k] - r["model"]).std(ddof=1) / np.sqrt(len(r[k])))}
        for k in names if k != "model"}
    out["temporal_std_ratio_generated_over_target"] = {
        k: {g: float(np.mean([d[g] for d in v])) for g in GROUPS} for k, v in std_ratio.items()}
    out["velocity_std_ratio_by_quarter"] = {k: np.mean(v, 0).tolist() for k, v in quarter.items()}
    curve = {k: np.mean(v, 0) for k, v in by_frame.items()}
    out["mae_by_frame_bin_channel_units"] = {
        f"{lo}-{lo + 15}": {k: float(c[lo - 1:lo + 15].mean()) for k, c in curve.items()}
        for lo in range(1, t.window, 16)}
    return out


def _bins(x: np.ndarray) -> dict:
    return {f"{lo}-{(hi or len(x)) - 1}": x[lo:hi] for lo, hi in BINS if lo < len(x)}


def part_decay(model, train, test, *, seed: int) -> dict:
    import jax.numpy as jnp

    from jaxgest.motion.datasets import load_clip_audio
    from jaxgest.zeggs import evaluate as ev
    from jaxgest.zeggs import features

    m = model.cfg.model
    lay = m.layout
    scale = np.asarray(model.input_scale)
    q0 = jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32)
    f0 = jnp.asarray([[0.0, 0.0, 1.0]], jnp.float32)
    z3 = jnp.zeros((1, 3), jnp.float32)
    rows = {}
    real_rows, path_rows = [], []
    for c in test:
        audio, sr = load_clip_audio(c)
        example = ev.style_example(c, train).motion
        e = model.style_embedding([example], seed=seed)  # as generate / evaluate (default temperature)
        speech, _ = model.speech(audio, sr=sr)
        s_emb = model.encode_speech(model.params, jnp.asarray(speech)[None])
        real = model.pose_features(c.motion)
        n = min(len(real), speech.shape[0])
        real = real[:n] * scale
        real_rows.append({g: {b: float(x[:, getattr(lay, g)].std(0).mean()) for b, x in _bins(real).items()}
                          for g in GROUPS})
        own = model.pose_features(c.motion)[:1]
        e_mu = model.style_embedding([example], seed=seed, temperature=0.0)
        e_own = model.style_embedding([c.motion], seed=seed, temperature=0.0)
        variants = {"inference_init": (model.pose_features(example)[:1], e), "true_init": (own, e),
                    "true_init_example_mean": (own, e_mu), "true_init_own_clip_style": (own, e_own),
                    "true_init_e0": (own, np.zeros_like(e)), "true_init_mean_speech": (own, e)}
        s_mean = model.encode_speech(model.params, jnp.zeros_like(jnp.asarray(speech)[None]))
        for k, (y0, ek) in variants.items():
            out = model.run_generator(model.params, s_mean if k == "true_init_mean_speech" else s_emb,
                                      jnp.asarray(ek)[None], jnp.asarray(y0), z3, q0, f0,
                                      model.pose_mean, model.pose_std)
            gen = np.asarray(out["pose"][0])[:n] * scale
            rows.setdefault(k, []).append({g: {b: float(x[:, getattr(lay, g)].std(0).mean())
                                               for b, x in _bins(gen).items()} for g in GROUPS})
            if k == "inference_init":  # rendering path: predicted channels vs the rendered motion's features
                motion = model.generate(audio, [example], sr=sr, seed=seed)
                rend = model.pose_stats.normalize(features.extract_features(motion)["features"])[:n] * scale
                path_rows.append({g: {"predicted_std": float(gen[:, getattr(lay, g)].std(0).mean()),
                                      "rendered_std": float(rend[:, getattr(lay, g)].std(0).mean()),
                                      "mae": float(np.abs(gen[:, getattr(lay, g)] - rend[:, getattr(lay, g)]).mean())}
                                  for g in GROUPS})

    def avg(rs):
        return {g: {b: float(np.mean([r[g][b] for r in rs])) for b in rs[0][g]} for g in rs[0]}

    real_avg = avg(real_rows)
    out = {"clips": len(test), "temporal_std_real": real_avg,
           "per_clip": {k: [{g: r[g] for g in ("local_positions", "local_velocities")} for r in rs]
                        for k, rs in list(rows.items()) + [("real", real_rows)]}}
    for k, rs in rows.items():
        a = avg(rs)
        out[f"temporal_std_generated_{k}"] = a
        out[f"ratio_generated_over_real_{k}"] = {g: {b: a[g][b] / max(real_avg[g][b], 1e-12) for b in a[g]}
                                                 for g in a}
    out["rendering_path"] = {g: {k: float(np.mean([r[g][k] for r in path_rows])) for k in path_rows[0][g]}
                             for g in GROUPS}
    return out


def _lagged(x: np.ndarray, past: int, future: int) -> np.ndarray:
    """``(F, C)`` -> ``(F, C * (past + future + 1))``: x[t + k] for k in [-past, future], edges repeated."""
    F = len(x)
    idx = np.clip(np.arange(F)[:, None] + np.arange(-past, future + 1)[None], 0, F - 1)
    return x[idx].reshape(F, -1)


def part_predictability(model, clips, *, ridge: float = 10.0) -> dict:
    """How much of the hands' speed a linear function of the speech energy around each frame explains.

    Per frame, the summed speed of both hands (root frame, cm/s) regressed (ridge) on the log energy and
    its positive difference (onset strength) at frame offsets ``[-past, +future]``, the speed's clip mean
    removed (the within-clip fluctuation: when the hands move); R^2 on the held-out style of
    leave-one-style-out folds (frames pooled). Model-free: it measures how far ahead the speech
    must be seen to anticipate the gestures (the small preset's speech encoder sees +-8 frames, the paper's
    +-16).
    """
    from jaxgest.motion import body
    from jaxgest.zeggs import data as zdata

    m = model.cfg.model
    zd = zdata.build(clips, fps=m.fps, mirror=False, speeds=(1.0,), pose_stats=model.pose_stats,
                     speech_stats=model.speech_stats, loudness=m.loudness, input_norm=m.input_norm)
    hands = body.joint_indices(zd.skeleton, body.HANDS)
    lay = m.layout
    seqs = []
    for s in zd.sequences:
        vel = s.pose[:, lay.local_velocities].reshape(len(s.pose), -1, 3)
        speed = np.linalg.norm(vel[:, hands], axis=-1).sum(-1)
        energy = zd.speech_stats.normalize(s.speech)[:, -1]
        onset = np.maximum(np.diff(energy, prepend=energy[0]), 0.0)
        seqs.append((s.style, np.stack([energy, onset], 1), speed - speed.mean()))
    contents = sorted({c for c, _, _ in seqs})
    out = {}
    for name, past, future in (("+-8 (small preset)", 8, 8), ("+-16 (paper)", 16, 16), ("+-32", 32, 32),
                               ("+-64", 64, 64), ("past 64 only", 64, 0), ("future 64 only", 0, 64)):
        res, tot = 0.0, 0.0
        for held in contents:
            tr = [(_lagged(x, past, future), y) for c, x, y in seqs if c != held]
            te = [(_lagged(x, past, future), y) for c, x, y in seqs if c == held]
            X = np.concatenate([a for a, _ in tr])
            y = np.concatenate([b for _, b in tr])
            mu, sd, ym = X.mean(0), X.std(0) + 1e-8, y.mean()
            Xs = (X - mu) / sd
            w = np.linalg.solve(Xs.T @ Xs + ridge * np.eye(Xs.shape[1]), Xs.T @ (y - ym))
            Xt = (np.concatenate([a for a, _ in te]) - mu) / sd
            yt = np.concatenate([b for _, b in te])
            res += float(np.sum((yt - (Xt @ w + ym)) ** 2))
            tot += float(np.sum((yt - yt.mean()) ** 2))
        out[name] = 1.0 - res / tot
    return out


def main(argv=None) -> int:
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import evaluate as ev
    from jaxgest.zeggs.inference import load_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batches", type=int, default=8, help="training-like batches for part 1")
    ap.add_argument("--parts", default="loss,decay")
    args = ap.parse_args(argv)

    model = load_model(args.workdir)
    clips = [c for c in load_folder(args.data) if c.audio is not None]
    train, test = ev._split_by_style(clips, args.seed)
    out = {"workdir": str(args.workdir), "data": str(args.data), "step": model.step,
           "units": "generator input units: (x - mean_c) / std_group"}
    parts = args.parts.split(",")
    if "loss" in parts:
        out["loss"] = part_loss(model, clips, batches=args.batches, seed=args.seed)
        lo = out["loss"]
        print(f"## 1. training windows ({lo['windows']} windows of {lo['window']} frames)\n")
        print("| predictor | recon loss (eq. 2) | − model (± SE) | MAE all | pos | rot | vel | ang vel | root vel | root ang |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for k, v in lo["mae_group_units"].items():
            d = lo["reconstruction_minus_model"].get(k)
            ds = "—" if d is None else f"{d['mean']:+.3f} ± {d['standard_error']:.3f}"
            print(f"| {k} | {lo['reconstruction_loss'][k]:.3f} | {ds} | {v['all']:.3f} | "
                  + " | ".join(f"{v[g]:.3f}" for g in GROUPS) + " |")
        print("\n| temporal std in the window, generated / target | " + " | ".join(GROUPS) + " |")
        print("|---|" + "---:|" * len(GROUPS))
        for k, v in lo["temporal_std_ratio_generated_over_target"].items():
            print(f"| {k} | " + " | ".join(f"{v[g]:.3f}" for g in GROUPS) + " |")
        for k, v in lo["velocity_std_ratio_by_quarter"].items():
            print(f"| {k}: local velocities by quarter of the window | " + " | ".join(f"{x:.3f}" for x in v) + " |")
        print("\n| frames | " + " | ".join(lo["mae_by_frame_bin_channel_units"]) + " |")
        for k in ("model", "mean_pose"):
            print(f"| {k} MAE (channel units) | " + " | ".join(f"{v[k]:.3f}" for v in lo["mae_by_frame_bin_channel_units"].values()) + " |")
    if "predictability" in parts:
        out["predictability_r2"] = part_predictability(model, clips)
        print("\n## hand speed from speech energy (ridge, leave-one-style-out R^2 of the within-clip fluctuation)\n")
        print("| speech frames seen | R^2 |\n|---|---:|")
        for k, v in out["predictability_r2"].items():
            print(f"| {k} | {v:.3f} |")
    if "decay" in parts:
        out["decay"] = part_decay(model, train, test, seed=args.seed)
        dc = out["decay"]
        print(f"\n## 2. temporal std generated / real, {dc['clips']} test clips\n")
        bins = list(dc["temporal_std_real"]["local_positions"])
        print("| init | group | " + " | ".join(bins) + " |")
        print("|---|---|" + "---:|" * len(bins))
        for k in [x[len("ratio_generated_over_real_"):] for x in dc if x.startswith("ratio_generated_over_real_")]:
            for g in GROUPS:
                r = dc[f"ratio_generated_over_real_{k}"][g]
                print(f"| {k} | {g} | " + " | ".join(f"{r[b]:.3f}" for b in bins) + " |")
        print("\n## 3. predicted channels vs rendered motion (inference init)\n")
        print("| group | predicted std | rendered std | MAE |\n|---|---:|---:|---:|")
        for g, v in dc["rendering_path"].items():
            print(f"| {g} | {v['predicted_std']:.3f} | {v['rendered_std']:.3f} | {v['mae']:.3f} |")
    pathlib.Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

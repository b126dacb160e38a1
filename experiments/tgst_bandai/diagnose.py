"""Autoencoder and swap diagnostics on the held-out clips: what the model does before any style is involved.

    python experiments/tgst_bandai/diagnose.py WORKDIR EVAL_DIR OUT.json [TRAIN_DIR] [--ae-step N] [--no-swap]
        [--edge-frames N] [--angles-only] [--contact-tolerance T]

1. Reconstruction against baselines with the same inputs (upper body, 13 joints, model rate, geodesic
   angle per joint, degrees): the autoencoder round trip (jaxgest.tgst.model.reconstruct: the clip-end
   handling of every encode path), PCA-16 (16 numbers per 4 frames, the autoencoder's latent budget, fitted
   on TRAIN_DIR's original clips, and as ``pca16_mix`` on the original + mirrored clips) and the mean pose
   (constant predictor, same data). Per joint, per clip and overall; also the first frame against the
   interior (frames 16 .. F-17) for the autoencoder. The lower body decoded from the upper latents: mean
   geodesic angle per joint and the fraction of joint-frames wrong by more than 90 deg (``lower_angle_deg``).
2. Round trips as motions: each held-out clip x is re-encoded and decoded (upper and lower body), written on
   x's skeleton as `jaxgest tgst transfer --method autoencoder` does (TGSTModel.to_motion), and compared
   with x: mean arm-joint speed ratio (world positions, forward differences, 8 arm joints) overall and on
   frames 0-5, per-joint interior speed ratio (frames 6 .. F-7), style and content error of the round trip
   under the world protocol and the authors' protocol (jaxgest.tgst.evaluate), and the foot criterion of
   issue 12: on the content's contact frames (``api.content_contact_frames``: its lowest foot/toe joint within
   1 cm of its clip minimum) the largest |output lowest foot - content lowest foot| and the fraction of those
   frames within 1 cm. ``--contact-tolerance T`` writes the round trips with that floor-contact tolerance
   (default: the API's, ``api.CONTACT_TOLERANCE``; 0 = per-frame contact).
3. Swap diagnostics (needs a trained transformer; skip with --no-swap) on the inter pairs of the held-out
   contents via jaxgest.tgst.model.swap_weights: mean largest soft-swap weight, effective number of blended
   style tokens 1 / sum w^2, fraction of content tokens whose argmax style token lies within +-1 index of
   the content token's own index, and the chance of that fraction (3 / Ns per token, clipped at the ends).

Without TRAIN_DIR the PCA and mean-pose baselines are skipped.
"""

from __future__ import annotations

import argparse
import json
import sys

import jax
import numpy as np

from jaxgest import metrics
from jaxgest.motion import body, datasets
from jaxgest.tgst import baselines
from jaxgest.tgst import model as tmodel
from jaxgest.tgst.autoencoder import angular_error_rad
from jaxgest.tgst.config import Config
from jaxgest.tgst.evaluate import clip_features, features_errors, make_pairs

TRUNK = ("Hips", "Spine", "Chest", "Neck", "Head")


def load_params(workdir, ae_step=None, transformer=True):
    """(cfg, params) of a workdir; the transformer is optional (an autoencoder-only workdir)."""
    import pathlib

    from jaxgest.tgst.trainer import ae_checkpointer, transformer_checkpointer

    stored = json.loads((pathlib.Path(workdir) / "config.json").read_text())
    cfg = Config.from_dict(stored["config"]).model
    template = jax.eval_shape(lambda k: tmodel.init_params(cfg, k), jax.random.key(0))
    ck = ae_checkpointer(workdir, cfg, read_only=True)
    params = {"autoencoder": ck.restore_params(template["autoencoder"], step=ae_step)}
    ck.close()
    if transformer:
        ck = transformer_checkpointer(workdir, cfg, None, read_only=True)
        params["transformer"] = ck.restore_params(template["transformer"])
        ck.close()
    return cfg, params


def body_upper_lower(motion, fps):
    bc = body.motion_to_body(datasets.resample_motion(motion, fps))
    return bc.upper.astype(np.float32), bc.lower.astype(np.float32)


def arm_speeds(m, arms=None) -> np.ndarray:
    """World speeds (m/s) of the 8 arm joints of motion ``m`` by forward differences: ``(F - 1, 8)``.

    The round trip's speed measure (section 2 of the module docstring); ``arms`` = their joint indices in
    ``m`` (default: looked up by name)."""
    from jaxgest.motion import kinematics
    from jaxgest.tgst.evaluate import _joint_indices

    arms = _joint_indices(m, body.ARMS) if arms is None else arms
    return np.linalg.norm(np.diff(kinematics.forward_kinematics(m)[:, arms], axis=0), axis=-1) * m.fps * 0.01


def speeds(arm_vel):
    """(F, 24) arm velocities -> (F, 8) speeds."""
    return np.linalg.norm(arm_vel.reshape(len(arm_vel), -1, 3), axis=-1)


def main(argv) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("workdir"), ap.add_argument("eval_dir"), ap.add_argument("out")
    ap.add_argument("train_dir", nargs="?")
    ap.add_argument("--ae-step", type=int, default=None)
    ap.add_argument("--no-swap", action="store_true")
    ap.add_argument("--angles-only", action="store_true", help="section 1 only (no round trips, no swap)")
    ap.add_argument("--edge-frames", type=int, default=None,
                    help="override the config's edge padding (0 = the old end-only padding, for comparison)")
    ap.add_argument("--contact-tolerance", type=float, default=None,
                    help="floor-contact tolerance of the round trips, cm (default: the API's; 0 = per frame)")
    args = ap.parse_args(argv[1:])
    cfg, params = load_params(args.workdir, args.ae_step, transformer=not args.no_swap)
    if args.edge_frames is not None:
        import dataclasses

        cfg = dataclasses.replace(cfg, edge_frames=args.edge_frames)
    rec_jit = jax.jit(lambda p, u: tmodel.reconstruct(p, u[None], cfg=cfg))

    def rec(p, u):  # the end replicated up to a multiple of 128 frames: fewer compilations, same real frames
        f = len(u)
        u = np.concatenate([u, np.repeat(u[-1:], -f % 128, axis=0)])
        return tuple(a[:, :f] for a in rec_jit(p, u))
    clips = datasets.load_folder(args.eval_dir, progress=False)
    held = [body_upper_lower(c.motion, cfg.fps) for c in clips]
    preset = json.loads(open(f"{args.workdir}/config.json").read())["preset"]
    report = {"workdir": args.workdir, "config": preset, "ae_step": args.ae_step, "num_clips": len(clips),
              "edge_frames": cfg.edge_frames}

    # ---- 1. angles: AE vs PCA-16 vs mean pose
    per_joint = {"autoencoder": []}
    first, interior = [], []
    ae_out, lower_err = [], []
    for up, lo in held:
        u_hat, l_hat = (np.asarray(a[0]) for a in rec(params["autoencoder"], up))
        ae_out.append((u_hat, l_hat))
        lower_err.append(np.degrees(np.asarray(angular_error_rad(l_hat, lo))))  # (F, 8), decoded from upper latents
        per_joint["autoencoder"].append(baselines.per_joint_angle_deg(u_hat, up))
        err = np.degrees(np.asarray(angular_error_rad(u_hat, up)))  # (F, 13)
        first.append(err[0].mean())
        interior.append(err[16:-16].mean() if len(err) > 40 else err.mean())
    if args.train_dir:
        import pathlib

        # fitted once per TRAIN_DIR (cache beside the workdirs): PCA-16 and mean pose on the original clips, and
        # PCA-16 / mean pose on the original + mirrored clips (the mirror of the data pipeline)
        ae = cfg.autoencoder
        cache = (pathlib.Path(args.workdir).resolve().parent
                 / f"recon_baselines_cache_v2_d{ae.latent_dim}_r{ae.time_reduction}_{cfg.fps:g}.npz")
        if cache.is_file():
            z = dict(np.load(cache))
        else:
            from jaxgest.tgst.data import mirror_motion

            train_clips = datasets.load_folder(args.train_dir, progress=False)
            orig = [body_upper_lower(c.motion, cfg.fps)[0] for c in train_clips]
            mirr = [body_upper_lower(mirror_motion(c.motion), cfg.fps)[0] for c in train_clips]
            z = {}
            for tag, data in (("", orig), ("_mix", orig + mirr)):
                pca = baselines.block_pca_fit(data, components=cfg.autoencoder.latent_dim,
                                              frames=cfg.autoencoder.time_reduction)
                z.update({f"pca_mean{tag}": pca["mean"], f"pca_basis{tag}": pca["basis"],
                          f"pca_frames{tag}": pca["frames"], f"mean_pose{tag}": baselines.mean_pose_fit(data)})
            np.savez(cache, **z)
        for tag, label in (("", "original clips"), ("_mix", "original + mirrored clips")):
            pca = {"mean": z[f"pca_mean{tag}"], "basis": z[f"pca_basis{tag}"], "frames": int(z[f"pca_frames{tag}"])}
            per_joint[f"pca16{tag}"] = [baselines.per_joint_angle_deg(baselines.block_pca_reconstruct(pca, up), up)
                                        for up, _ in held]
            per_joint[f"mean_pose{tag}"] = [baselines.per_joint_angle_deg(z[f"mean_pose{tag}"], up)
                                            for up, _ in held]
        report["baselines_fitted_on"] = {"pca16": "original training clips", "mean_pose": "original training clips",
                                         "pca16_mix": "original + mirrored (tgst.data.mirror_motion)",
                                         "mean_pose_mix": "original + mirrored (tgst.data.mirror_motion)"}
    joints = list(body.UPPER)
    report["clips"] = [c.path.name for c in clips]
    report["angle_deg"] = {
        k: {"mean": float(np.mean(v)), "per_joint": dict(zip(joints, np.mean(v, axis=0).round(3).tolist())),
            "per_clip": np.mean(v, axis=1).round(4).tolist(),
            "per_clip_joint": np.round(v, 3).tolist()}
        for k, v in per_joint.items()}
    print("mean geodesic angle per joint (deg), held-out clips:")
    print(f"{'joint':<12}" + "".join(f"{k:>14}" for k in per_joint))
    for j, name in enumerate(joints + ["mean"]):
        print(f"{name:<12}" + "".join(f"{(np.mean(v, axis=0)[j] if j < len(joints) else np.mean(v)):>14.2f}"
                                      for v in per_joint.values()))
    report["lower_angle_deg"] = {  # the lower decoder (from the upper body's latents), geodesic per joint
        "mean": float(np.mean([e.mean() for e in lower_err])),
        "per_joint": dict(zip(body.LOWER, np.mean([e.mean(0) for e in lower_err], 0).round(3).tolist())),
        "gross_frac": float(np.mean([(e > 90).mean() for e in lower_err])),  # joint-frames > 90 deg, per clip
        "per_clip": [round(float(e.mean()), 3) for e in lower_err]}
    print(f"lower body (decoded from the upper latents): {report['lower_angle_deg']['mean']:.2f} deg, "
          f"{report['lower_angle_deg']['gross_frac']:.2%} of joint-frames > 90 deg")
    report["ae_first_frame_deg"] = float(np.mean(first))
    report["ae_interior_deg"] = float(np.mean(interior))

    if args.angles_only:
        with open(args.out, "w") as f:
            json.dump(report, f, indent=1)
        print(json.dumps({k: v["mean"] for k, v in report["angle_deg"].items()}, indent=1))
        return 0

    # ---- 2. round trips as motions at the clip rate (written like `jaxgest tgst transfer` writes a result)
    report["roundtrip"] = roundtrip(cfg, clips, ae_out, tolerance=args.contact_tolerance)

    # ---- 3. swap diagnostics on inter pairs
    if not args.no_swap:
        sw = jax.jit(lambda p, c, s: tmodel.swap_weights(p, c[None], s[None], cfg=cfg)[0])
        idx = {c.path: i for i, c in enumerate(clips)}
        out = []
        for pair in make_pairs(clips, "inter"):
            c_up, s_up = held[idx[pair.content.path]][0], held[idx[pair.style.path]][0]
            out.append(swap_stats(np.asarray(sw(params, c_up, s_up))))
        report["swap_inter"] = {"num_pairs": len(out), **{k: float(np.mean([o[k] for o in out])) for k in out[0]}}
    with open(args.out, "w") as f:
        json.dump(report, f, indent=1)
    print(json.dumps({k: v for k, v in report.items() if k != "roundtrip"}, indent=1))
    print(json.dumps({k: v for k, v in report["roundtrip"].items() if k != "clips"}, indent=1))
    return 0


def roundtrip(cfg, clips, outs, tolerance=None) -> dict:
    """Section 2 for any reconstruction: ``outs`` = ``(upper, lower)`` exp-maps at the model rate per clip of
    ``clips``, written as motions on each clip's skeleton (``TGSTModel.to_motion`` with floor-contact
    ``tolerance``, default the API's) and compared with it."""
    from jaxgest.tgst import api
    from jaxgest.tgst.api import TGSTModel
    from jaxgest.tgst.evaluate import _joint_indices, get_protocol

    writer = TGSTModel(cfg, None)
    tolerance = api.CONTACT_TOLERANCE if tolerance is None else tolerance
    rows = []
    for clip, (u_hat, l_hat) in zip(clips, outs):
        x = clip.motion
        y = writer.to_motion(u_hat, l_hat, x, tolerance=tolerance)
        foot = foot_criterion(y, x)
        arms = _joint_indices(x, body.ARMS)
        sx, sy = arm_speeds(x, arms), arm_speeds(y, arms)  # (F-1, 8) world arm-joint speeds, m/s
        r = {"clip": clip.path.name, "speed_ratio": float(sy.mean() / sx.mean()),
             "speed_ratio_0_5": float(sy[:6].mean() / sx[:6].mean()),
             "joint_interior_ratio": (sy[6:-6].mean(0) / sx[6:-6].mean(0)).tolist(),
             "first_step_speed": float(sy[0].mean()), "first_step_speed_input": float(sx[0].mean()), **foot}
        window = metrics.window_for_fps(x.fps)
        for proto in ("world", "authors"):
            try:
                fx = clip_features(x, protocol=proto)
                e = features_errors(clip_features(y, protocol=proto), fx, clip_features(x, protocol=proto,
                                    reference=get_protocol(proto).mirror_style), window=window)
                r[f"style_{proto}"], r[f"content_{proto}"] = e["style"]["mean"], e["content"]["mean"]
            except Exception as err:  # too short for the protocol's cut or one window
                r[f"skipped_{proto}"] = str(err)
        rows.append(r)
    jr = np.array([r["joint_interior_ratio"] for r in rows])
    return {
        "speed_ratio": float(np.mean([r["speed_ratio"] for r in rows])),
        "speed_ratio_0_5": float(np.mean([r["speed_ratio_0_5"] for r in rows])),
        "first_step_speed": float(np.mean([r["first_step_speed"] for r in rows])),
        "first_step_speed_input": float(np.mean([r["first_step_speed_input"] for r in rows])),
        "joint_interior_ratio": dict(zip(body.ARMS, jr.mean(0).round(3).tolist())),
        **{f"{k}_{p}": float(np.mean([r[f"{k}_{p}"] for r in rows if f"{k}_{p}" in r]))
           for k in ("style", "content") for p in ("world", "authors")},
        **{f"clips_{p}": sum(f"style_{p}" in r for r in rows) for p in ("world", "authors")},
        "contact_tolerance": tolerance,
        "foot_max_dev": float(max(r["foot_max_dev"] for r in rows)),
        "foot_within_1cm": float(sum(r["foot_within_1cm"] * r["contact_frames"] for r in rows)
                                 / max(1, sum(r["contact_frames"] for r in rows))),
        "clips": rows}


def foot_criterion(y, x) -> dict:
    """Issue 12's foot criterion of an output ``y`` written on content ``x``: on x's contact frames
    (``api.content_contact_frames``) the largest |lowest foot/toe height of y - that of x| (file units, cm on
    Bandai-Namco) and the fraction of contact frames where it is below 1 cm."""
    from jaxgest.motion import root_motion
    from jaxgest.tgst import api

    feet = api.foot_names(x.skeleton)
    contact = api.content_contact_frames(x)
    dev = np.abs(root_motion.lowest_foot_height(y, feet) - root_motion.lowest_foot_height(x, feet))[contact]
    return {"contact_frames": int(contact.sum()), "foot_max_dev": float(dev.max()) if len(dev) else 0.0,
            "foot_within_1cm": float((dev < 1.0).mean()) if len(dev) else 1.0}


def swap_stats(w: np.ndarray) -> dict:
    """Diagnostics of one soft-swap weight matrix ``(Nc, Ns)`` (rows on the simplex)."""
    nc, ns = w.shape
    arg = w.argmax(-1)
    n = np.arange(nc)
    near = np.abs(arg - n) <= 1
    lo, hi = np.clip(n - 1, 0, ns - 1), np.clip(n + 1, 0, ns - 1)
    chance = np.where(n < ns, (hi - lo + 1) / ns, np.where(n - 1 < ns, 1 / ns, 0.0))
    return {"max_weight": float(w.max(-1).mean()), "effective_tokens": float((1.0 / np.sum(w ** 2, axis=-1)).mean()),
            "argmax_within_1": float(near.mean()), "chance_within_1": float(chance.mean())}


if __name__ == "__main__":
    sys.exit(main(sys.argv))

"""Does a fixed temporal low-pass on the decoded exp-maps remove the round trip's excess speed without the
angle cost of the displacement term? Inference only, no training.

    python output_filter.py OUT.json WORKDIR [WORKDIR ...] --eval out/data_eval --ae-step 500 \
        --sigmas 0 0.75 1 1.5 2 [--contact-tolerance 0.9]

For each workdir and Gaussian width sigma (frames at the model rate; 0 = no filter), the autoencoder round
trip of every held-out clip (``diagnose.py``'s path) is filtered along time (``gaussian_smooth``: edge
frames replicated, per exp-map channel) and scored as ``diagnose.py`` scores it: held-out angle per joint
and the round-trip speed ratios (world arm speeds, output / input; tube contact by default). Controls in
the same run: the same filter on the *input* itself (what the filter does to real motion: angle and speed
lost), and on the PCA-16 reconstruction (fitted on the original training clips: ``diagnose.py``'s cache),
so a filter that helps any reconstruction is not credited to the autoencoder.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import jax
import numpy as np

from jaxgest.motion import datasets
from jaxgest.tgst import baselines
from jaxgest.tgst import model as tmodel
from jaxgest.tgst.autoencoder import upper_joint_channels

from diagnose import body_upper_lower, load_params, roundtrip


def gaussian_smooth(x: np.ndarray, sigma: float) -> np.ndarray:
    """(F, C) filtered along F by a normalised Gaussian of width ``sigma`` frames (radius 3 sigma), the edge
    frames replicated; sigma 0 returns x."""
    if sigma <= 0:
        return x
    r = int(np.ceil(3 * sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    xp = np.concatenate([np.repeat(x[:1], r, 0), x, np.repeat(x[-1:], r, 0)])
    return np.stack([np.convolve(xp[:, c], k, mode="valid") for c in range(x.shape[1])], 1).astype(x.dtype)


def score(cfg, clips, held, outs, tol, pca_mean_pose=None) -> dict:
    ang = [baselines.per_joint_angle_deg(u_hat, up) for (u_hat, _), (up, _) in zip(outs, held)]
    rt = roundtrip(cfg, clips, outs, tolerance=tol)
    j = list(rt["joint_interior_ratio"].values())
    return {"angle_deg": float(np.mean(ang)), "per_clip_angle": np.mean(ang, axis=1).round(4).tolist(),
            "speed_ratio": rt["speed_ratio"], "speed_ratio_0_5": rt["speed_ratio_0_5"],
            "per_clip_speed": [r["speed_ratio"] for r in rt["clips"]],
            "joint_ratio_min": min(j), "joint_ratio_max": max(j), "joints": rt["joint_interior_ratio"],
            "style_world": rt["style_world"], "style_authors": rt["style_authors"]}


def main(argv) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("out"), ap.add_argument("workdirs", nargs="+")
    ap.add_argument("--eval", default="out/data_eval")
    ap.add_argument("--ae-step", type=int, default=None)
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0, 0.75, 1.0, 1.5, 2.0])
    ap.add_argument("--contact-tolerance", type=float, default=0.9)
    ap.add_argument("--controls", action="store_true", help="also filter the input and PCA-16")
    ap.add_argument("--true-joints", nargs="*", default=[], metavar="J1,J2",
                    help="also score each sigma with these upper-body joints (comma-separated groups) taken "
                         "from the input instead of the output: which joints' errors make the excess speed")
    args = ap.parse_args(argv[1:])
    clips = datasets.load_folder(args.eval, progress=False)
    report = {"eval": args.eval, "contact_tolerance": args.contact_tolerance, "runs": {}}
    cfg = None
    for wd in args.workdirs:
        cfg, params = load_params(wd, args.ae_step, transformer=False)
        held = [body_upper_lower(c.motion, cfg.fps) for c in clips]
        rec_jit = jax.jit(lambda p, u: tmodel.reconstruct(p, u[None], cfg=cfg))

        def rec(u):
            f = len(u)
            u = np.concatenate([u, np.repeat(u[-1:], -f % 128, axis=0)])
            return tuple(np.asarray(a[0, :f]) for a in rec_jit(params["autoencoder"], u))
        raw = [rec(up) for up, _ in held]
        for s in args.sigmas:
            outs = [(gaussian_smooth(u, s), gaussian_smooth(l, s)) for u, l in raw]
            r = score(cfg, clips, held, outs, args.contact_tolerance)
            report["runs"][f"{pathlib.Path(wd).name}|sigma={s:g}"] = r
            print(f"{pathlib.Path(wd).name:<22} sigma {s:<5g} angle {r['angle_deg']:.3f}  speed "
                  f"{r['speed_ratio']:.3f} / {r['speed_ratio_0_5']:.3f}  joints {r['joint_ratio_min']:.2f}-"
                  f"{r['joint_ratio_max']:.2f}", flush=True)
            for group in args.true_joints:
                cols = upper_joint_channels(group.split(","))
                swapped = []
                for (u, l), (up, _) in zip(outs, held):
                    u = u.copy()
                    u[:, cols] = up[:, cols]
                    swapped.append((u, l))
                r = score(cfg, clips, held, swapped, args.contact_tolerance)
                report["runs"][f"{pathlib.Path(wd).name}|sigma={s:g}|true={group}"] = r
                print(f"  true {group:<30} angle {r['angle_deg']:.3f}  speed {r['speed_ratio']:.3f} / "
                      f"{r['speed_ratio_0_5']:.3f}  joints {r['joint_ratio_min']:.2f}-{r['joint_ratio_max']:.2f}",
                      flush=True)
    if args.controls:
        cache = sorted(pathlib.Path(args.workdirs[0]).resolve().parent.glob("recon_baselines_cache_v2_*.npz"))
        z = dict(np.load(cache[0]))
        pca = {"mean": z["pca_mean"], "basis": z["pca_basis"], "frames": int(z["pca_frames"])}
        held = [body_upper_lower(c.motion, cfg.fps) for c in clips]
        for s in args.sigmas:
            for tag, outs in (("input", [(gaussian_smooth(u, s), gaussian_smooth(l, s)) for u, l in held]),
                              ("pca16", [(gaussian_smooth(baselines.block_pca_reconstruct(pca, u), s),
                                          gaussian_smooth(l, s)) for u, l in held])):
                r = score(cfg, clips, held, outs, args.contact_tolerance)
                report["runs"][f"control_{tag}|sigma={s:g}"] = r
                print(f"control {tag:<14} sigma {s:<5g} angle {r['angle_deg']:.3f}  speed "
                      f"{r['speed_ratio']:.3f} / {r['speed_ratio_0_5']:.3f}  joints {r['joint_ratio_min']:.2f}-"
                      f"{r['joint_ratio_max']:.2f}", flush=True)
    with open(args.out, "w") as f:
        json.dump(report, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

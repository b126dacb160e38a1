"""Floor contact of the autoencoder round trip: per-frame contact vs a tube of tolerance tol (taut string).

    python experiments/tgst_bandai/contact_tube.py WORKDIR EVAL_DIR OUT.json [--ae-step N]
    python experiments/tgst_bandai/contact_tube.py table OUT.json [OUT.json ...]   # markdown, paired per clip

Each held-out clip x is re-encoded and decoded (``jaxgest.tgst.model.reconstruct``, as diagnose.py section 2),
resampled and written on x's skeleton with x's root path (``body.body_to_motion(..., floor=False)``: the
content's own root height), then its root height is set by each contact variant:

* ``frame``: the per-frame contact (``content_floor_contact(tolerance=0)`` = ``RM.floor_contact``): the
  lowest foot/toe joint at the content's lowest foot/toe height on every frame;
* ``tube_T`` (T in cm): ``RM.floor_contact_tube`` with tolerance T on the content's contact frames
  (``api.content_contact_frames``: the content's lowest foot joint within 1 cm of its clip minimum, the
  frames of the issue's foot criterion, as tests/test_tgst_api.py defines them), the other frames free;
  ``tube_0`` differs from ``frame`` only on the non-contact frames;
* ``lazy_0.9``: the other exact least-total-variation path (play operator: hold the shift until it leaves the
  tube, then move it just back in, started at the level the first forced move needs), for comparison;
* ``content_root``: control, no contact (the content's own root height);
* ``true_legs``: control, the input's lower body with the decoded upper body, per-frame contact;
  ``true_legs_tube_0.9`` the same with the tube.

Per clip and variant: world arm-joint speed ratio (8 arm joints, forward differences, output / input) overall
and on frames 0-5, per-joint interior ratio (frames 6 .. F-7), round-trip style and content error (world and
authors' protocols, ``jaxgest.tgst.evaluate``), the foot criterion (max |output lowest foot - content lowest
foot| over contact frames, fraction of contact frames within 1 cm), and the per-frame shift series
s(t) = content lowest(t) - decoded lowest(t) (decoded written with the content's root height): its spread
(std), mean |s(t+1) - s(t)| in cm/s against the content root's vertical speed, and each variant's shift path's
total variation. Upper-body angle error (unchanged by the contact) once per clip.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

import jax
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from diagnose import arm_speeds, body_upper_lower, load_params  # noqa: E402

TOLS = (0.0, 0.25, 0.5, 0.9)


def lazy_path(lo, hi) -> np.ndarray:
    """Play-operator path through ``lo <= x <= hi`` (free frames: +-inf): constant until forced, then the
    smallest move back into the tube; started at the level the first forced move needs (least total variation,
    but each move is made on one frame)."""
    on = np.isfinite(lo)
    idx = np.flatnonzero(on)
    x = np.zeros(len(lo))
    if not len(idx):
        return x
    top, bot = hi[idx[0]], lo[idx[0]]
    level = None
    for k in idx[1:]:
        if lo[k] > top:
            level = top
            break
        if hi[k] < bot:
            level = bot
            break
        top, bot = min(top, hi[k]), max(bot, lo[k])
    cur = 0.5 * (top + bot) if level is None else level
    for k in range(len(lo)):
        if on[k]:
            cur = min(max(cur, lo[k]), hi[k])
        x[k] = cur
    return x


def main(argv) -> int:
    from jaxgest import metrics
    from jaxgest.motion import body, datasets
    from jaxgest.motion import kinematics as
    from jaxgest.motion import root_motion as RM K
    from jaxgest.tgst import api
    from jaxgest.tgst import model as tmodel
    from jaxgest.tgst.autoencoder import angular_error_rad
    from jaxgest.tgst.evaluate import _joint_indices, clip_features, features_errors, get_protocol

    ap = argparse.ArgumentParser()
    ap.add_argument("workdir"), ap.add_argument("eval_dir"), ap.add_argument("out")
    ap.add_argument("--ae-step", type=int, default=None)
    args = ap.parse_args(argv[1:])
    cfg, params = load_params(args.workdir, args.ae_step, transformer=False)
    rec_jit = jax.jit(lambda p, u: tmodel.reconstruct(p, u[None], cfg=cfg))
    clips = datasets.load_folder(args.eval_dir, progress=False)
    rows = []
    for clip in clips:
        x = clip.motion
        up, lo = body_upper_lower(x, cfg.fps)
        f = len(up)
        upad = np.concatenate([up, np.repeat(up[-1:], -f % 128, axis=0)])  # as diagnose.py: few compilations
        u_hat, l_hat = (np.asarray(a)[0, :f] for a in rec_jit(params["autoencoder"], upad))
        angle = float(np.degrees(np.asarray(angular_error_rad(u_hat, up))).mean())
        F = x.num_frames
        feet = api.foot_names(x.skeleton)
        c_low = RM.lowest_foot_height(x, feet)
        contact = api.content_contact_frames(x)
        written = {}
        for legs, lower in (("decoded", l_hat), ("true", lo)):
            u = api.resample_body(u_hat, cfg.fps, x.fps, F)
            w = api.resample_body(lower, cfg.fps, x.fps, F)
            written[legs] = body.body_to_motion(u, w, x, floor=False)
        s = c_low - RM.lowest_foot_height(written["decoded"], feet)  # per-frame shift of today's contact
        variants = {"frame": api.content_floor_contact(written["decoded"], x, tolerance=0.0),
                    "content_root": written["decoded"],
                    "true_legs": api.content_floor_contact(written["true"], x, tolerance=0.0),
                    "true_legs_tube_0.9": api.content_floor_contact(written["true"], x, tolerance=0.9)}
        for tol in TOLS:
            variants[f"tube_{tol:g}"] = RM.floor_contact_tube(written["decoded"], feet=feet, height=c_low,
                                                             tolerance=tol, contact=contact)
        lazy = lazy_path(np.where(contact, s - 0.9, -np.inf), np.where(contact, s + 0.9, np.inf))
        variants["lazy_0.9"] = RM.shift_root_height(written["decoded"], lazy)
        arms = _joint_indices(x, body.ARMS)
        sx = arm_speeds(x, arms)
        fx = {}
        for p in ("world", "authors"):
            try:
                fx[p] = clip_features(x, protocol=p)
            except Exception:  # too short for the protocol's cut: that protocol is skipped for the clip
                pass
        window = metrics.window_for_fps(x.fps)
        hips = K.forward_kinematics(x)[:, K._hips_index(x.skeleton), x.skeleton.up_axis]
        r = {"clip": clip.path.name, "frames": F, "fps": x.fps, "angle_deg": angle,
             "contact_frames": int(contact.sum()),
             "shift": {"std_cm": float(s.std()), "abs_mean_cm": float(abs(s.mean())),
                       "mean_abs_step_cm_s": float(np.abs(np.diff(s)).mean() * x.fps),
                       "max_abs_step_cm": float(np.abs(np.diff(s)).max()),
                       "tv_cm": float(np.abs(np.diff(s)).sum()),
                       "content_root_vertical_speed_cm_s": float(np.abs(np.diff(hips)).mean() * x.fps)},
             "variants": {}}
        ref_y = RM.lowest_foot_height(written["decoded"], feet)
        for name, y in variants.items():
            sy = arm_speeds(y, arms)
            o_low = RM.lowest_foot_height(y, feet)
            dev = np.abs(o_low - c_low)[contact]
            base = RM.lowest_foot_height(written["true"], feet) if name.startswith("true") else ref_y
            shift_path = o_low - base
            v = {"speed_ratio": float(sy.mean() / sx.mean()),
                 "speed_ratio_0_5": float(sy[:6].mean() / sx[:6].mean()),
                 "joint_interior_ratio": (sy[6:-6].mean(0) / sx[6:-6].mean(0)).tolist(),
                 "foot_max_dev_cm": float(dev.max()) if len(dev) else 0.0,
                 "foot_within_1cm": float((dev < 1.0).mean()) if len(dev) else 1.0,
                 "shift_tv_cm": float(np.abs(np.diff(shift_path)).sum()),
                 "shift_max_step_cm": float(np.abs(np.diff(shift_path)).max())}
            for proto in ("world", "authors"):
                try:
                    if proto not in fx:
                        raise ValueError(f"clip too short for the {proto} protocol")
                    ref = clip_features(x, protocol=proto, reference=get_protocol(proto).mirror_style)
                    e = features_errors(clip_features(y, protocol=proto), fx[proto], ref, window=window)
                    v[f"style_{proto}"], v[f"content_{proto}"] = e["style"]["mean"], e["content"]["mean"]
                except Exception as err:  # too short for the protocol's cut or one window
                    v[f"skipped_{proto}"] = str(err)
            r["variants"][name] = v
        rows.append(r)
        print(clip.path.name, F, int(contact.sum()),
              {k: round(v["speed_ratio"], 3) for k, v in r["variants"].items()}, flush=True)
    out = {"workdir": args.workdir, "ae_step": args.ae_step, "contact_band_cm": api.CONTACT_BAND,
           "clips": rows}
    pathlib.Path(args.out).write_text(json.dumps(out, indent=1))
    return 0


def _pm(d, lower=True):
    """Mean +- standard error over clips (and how many clips are below 0)."""
    d = np.asarray(d, float)
    txt = f"{d.mean():+.3f} +- {d.std(ddof=1) / np.sqrt(len(d)):.3f}"
    return txt + (f" ({int((d < -1e-9).sum())}/{len(d)})" if lower else "")


def table(paths) -> None:
    """Markdown tables of one or more runs (seeds): means over clips (and runs), paired against ``frame``."""
    from jaxgest.motion import body

    runs = [json.loads(pathlib.Path(p).read_text()) for p in paths]
    names = list(runs[0]["clips"][0]["variants"])
    allc = [c for r in runs for c in r["clips"]]
    clip_names = [c["clip"] for c in runs[0]["clips"]]
    assert all([c["clip"] for c in r["clips"]] == clip_names for r in runs), "runs on different clips"

    def col(name, key):
        """Per clip, averaged over the runs (seeds): the unit of the paired statistics is the clip."""
        return np.mean([[c["variants"][name].get(key, np.nan) for c in r["clips"]] for r in runs], axis=0)

    sh = {k: np.mean([[c["shift"][k] for c in r["clips"]] for r in runs], axis=0) for k in allc[0]["shift"]}
    print(f"runs: {', '.join(paths)} (per clip averaged over runs; +- = SE over {len(clip_names)} clips, "
          f"(k/n) = clips below 0); {len(allc)} clip round trips; angle (deg, all variants) "
          f"{np.mean([c['angle_deg'] for c in allc]):.2f}; contact frames "
          f"{sum(c['contact_frames'] for c in allc)} / {sum(c['frames'] for c in allc)}")
    print(f"shift s(t): |clip mean| {sh['abs_mean_cm'].mean():.2f} cm, std {sh['std_cm'].mean():.2f} cm, "
          f"mean |step| {sh['mean_abs_step_cm_s'].mean():.2f} cm/s (content root vertical speed "
          f"{sh['content_root_vertical_speed_cm_s'].mean():.2f} cm/s), max step "
          f"{sh['max_abs_step_cm'].mean():.2f} cm (mean of clip maxima), TV {sh['tv_cm'].mean():.1f} cm\n")
    print("| contact | arm speed ratio overall / 0-5 | - frame, overall (paired) | - frame, 0-5 (paired) | "
          "per-joint interior ratio (shoulders / upper arms / lower arms / hands) | "
          "style world / authors (m/s) | "
          "content world (m) | foot max dev on contact frames (cm): mean / max over clips | within 1 cm | "
          "shift TV (cm) / max step (cm) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in names:
        jr = np.array([c["variants"][n]["joint_interior_ratio"] for c in allc]).mean(0)  # all round trips
        j = dict(zip(body.ARMS, jr))
        groups = [[v for k, v in j.items() if g in k] for g in ("Shoulder", "UpperArm", "LowerArm", "Hand")]
        jtxt = " / ".join(f"{min(g):.2f}-{max(g):.2f}" for g in groups)
        dev = col(n, "foot_max_dev_cm")
        print(f"| {n} | {col(n, 'speed_ratio').mean():.3f} / {col(n, 'speed_ratio_0_5').mean():.3f} "
              f"(median {np.median(col(n, 'speed_ratio')):.3f}) | "
              f"{_pm(col(n, 'speed_ratio') - col('frame', 'speed_ratio'))} | "
              f"{_pm(col(n, 'speed_ratio_0_5') - col('frame', 'speed_ratio_0_5'))} | {jtxt} | "
              f"{np.nanmean(col(n, 'style_world')):.3f} / {np.nanmean(col(n, 'style_authors')):.3f} | "
              f"{np.nanmean(col(n, 'content_world')):.3f} | {dev.mean():.2f} / "
              f"{max(c['variants'][n]['foot_max_dev_cm'] for c in allc):.2f} | "
              f"{col(n, 'foot_within_1cm').mean():.3f} | {col(n, 'shift_tv_cm').mean():.1f} / "
              f"{col(n, 'shift_max_step_cm').mean():.2f} |")
    fr, cr = col("frame", "speed_ratio"), col("content_root", "speed_ratio")
    print(f"\nexcess arm speed explained by the per-frame shift: (frame - content_root) / (frame - 1) = "
          f"{(fr.mean() - cr.mean()) / (fr.mean() - 1):.2f}")
    for n in names:
        if n.startswith("tube") or n.startswith("lazy"):
            print(f"{n}: share of the per-frame excess over content_root removed "
                  f"{(fr.mean() - col(n, 'speed_ratio').mean()) / (fr.mean() - cr.mean()):.2f}; "
                  f"- content_root (paired) {_pm(col(n, 'speed_ratio') - cr)}")
    for n in ("content_root", "tube_0.5", "tube_0.9"):
        for proto in ("world", "authors"):
            a = col(n, f"style_{proto}") - col("frame", f"style_{proto}")
            a = a[np.isfinite(a)]
            print(f"style {proto}: {n} - frame {_pm(a)} ({len(a)} clips)")
    a = col("tube_0.9", "content_world") - col("frame", "content_world")
    print(f"content world: tube_0.9 - frame {_pm(a[np.isfinite(a)])}")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "table":
        table(sys.argv[2:])
    else:
        sys.exit(main(sys.argv))

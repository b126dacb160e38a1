"""Where does the style error of TGST results come from? Autoencoder round trips of the held-out clips.

    python experiments/tgst_bandai/diagnose.py WORKDIR EVAL_DIR OUT.json [TRAIN_DIR]

For every held-out clip x (all styles), each variant below is written back on x's skeleton with
jaxgest.motion.body.body_to_motion (x's root path, feet on the floor, as `jaxgest tgst transfer` does) and
scored against x itself with the evaluation's errors (content error, m; style error, m/s) plus the mean
arm-joint speed (m/s):

* roundtrip: x's own body exp-maps, no network (the conversion and floor placement alone);
* ae_upper: the autoencoder's reconstruction of the upper body, x's own lower body;
* ae_full: the autoencoder's reconstruction of both halves (the lower body decoded from the upper latents),
  i.e. a transfer with a perfect identity swap.

The autoencoder's mean angular reconstruction error (degrees, upper body, at the model rate) is reported
for the held-out clips and, when TRAIN_DIR is given, for the training clips (paper §4.1 compares the two).
It also reports how sharp the soft swap (eq. 4) is on the intra-scenario pairs of the held-out contents:
the mean over content tokens of the largest swap weight (1 = the hard swap of eq. 19) and of the
effective number of style tokens blended, exp(entropy).
"""

from __future__ import annotations

import json
import sys

import jax
import numpy as np

from jaxgest import metrics
from jaxgest.motion import body, datasets
from jaxgest.tgst import model as tmodel
from jaxgest.tgst.api import load_model, resample_body
from jaxgest.tgst.autoencoder import mean_angular_error_deg
from jaxgest.tgst.evaluate import clip_features, features_errors
from jaxgest.tgst.tokens import pad_frames, trim_frames  # the padding of transfer_arrays


def main(argv) -> int:
    workdir, data_dir, out = argv[1:4]
    train_dir = argv[4] if len(argv) > 4 else None
    m = load_model(workdir)
    cfg = m.cfg

    @jax.jit
    def recon(upper):
        z = tmodel.encode(m.params["autoencoder"], pad_frames(upper, cfg.frame_multiple, min_frames=cfg.min_frames),
                          cfg=cfg)
        u, lo = tmodel.decode(m.params["autoencoder"], z, cfg=cfg)
        return trim_frames(u, upper.shape[1]), trim_frames(lo, upper.shape[1])

    def angle(clip_list):
        out = []
        for c in clip_list:
            up = body.motion_to_body(datasets.resample_motion(c.motion, cfg.fps)).upper.astype(np.float32)[None]
            out.append(float(mean_angular_error_deg(recon(up)[0], up)[0]))
        return float(np.mean(out))

    rows = {k: [] for k in ("clip", "roundtrip", "ae_upper", "ae_full")}
    clips = datasets.load_folder(data_dir, progress=False)
    for clip in clips:
        x = clip.motion
        F = x.num_frames
        bc = body.motion_to_body(datasets.resample_motion(x, cfg.fps))
        u, lo = (np.asarray(a[0]) for a in recon(bc.upper.astype(np.float32)[None]))
        true_u = resample_body(bc.upper.astype(np.float32), cfg.fps, x.fps, F)
        true_l = resample_body(bc.lower.astype(np.float32), cfg.fps, x.fps, F)
        ae_u, ae_l = resample_body(u, cfg.fps, x.fps, F), resample_body(lo, cfg.fps, x.fps, F)
        fx = clip_features(x)
        window = metrics.window_for_fps(x.fps)
        if len(fx[1]) < window:
            continue
        rows["clip"].append({"speed": float(np.linalg.norm(fx[1].reshape(len(fx[1]), -1, 3), axis=-1).mean())})
        for name, (uu, ll) in {"roundtrip": (true_u, true_l), "ae_upper": (ae_u, true_l),
                               "ae_full": (ae_u, ae_l)}.items():
            y = body.body_to_motion(uu, ll, x, floor=True)
            fy = clip_features(y)
            e = features_errors(fy, fx, fx, window=window)
            rows[name].append({"content": e["content"]["mean"], "style": e["style"]["mean"],
                               "speed": float(np.linalg.norm(fy[1].reshape(len(fy[1]), -1, 3), axis=-1).mean())})
    from jaxgest.tgst.evaluate import make_pairs
    from jaxgest.tgst.model import transfer_arrays

    soft = jax.jit(lambda p, c, st: transfer_arrays(p, c, st, cfg=cfg, method="soft")[2]["swap_weights"])
    sharp = []
    for pair in make_pairs(clips, "intra"):
        c = m.body_arrays(pair.content.motion, "content")[None]
        st = m.body_arrays(pair.style.motion, "style")[None]
        w = np.asarray(soft(m.params, c, st))[0]  # (Nc, Ns)
        ent = -(w * np.log(np.clip(w, 1e-12, None))).sum(-1)
        sharp.append({"max_weight": float(w.max(-1).mean()), "effective_tokens": float(np.exp(ent).mean())})
    ae_angle = {"held_out": angle(clips)}
    if train_dir is not None:
        ae_angle["train"] = angle(datasets.load_folder(train_dir, progress=False))
    report = {"workdir": workdir, "data": data_dir, "num_clips": len(rows["clip"]),
              "mean": {k: {m_: float(np.mean([r[m_] for r in v])) for m_ in v[0]} for k, v in rows.items()},
              "ae_angle_deg": ae_angle,
              "soft_swap": {"num_pairs": len(sharp), **{k: float(np.mean([r[k] for r in sharp])) for k in sharp[0]}}}
    with open(out, "w") as f:
        json.dump(report, f, indent=1)
    print(json.dumps({k: report[k] for k in ("mean", "ae_angle_deg", "soft_swap")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

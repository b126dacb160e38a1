"""Oracle swaps: how much content can ANY collage of the style clip's tokens keep? No training involved.

    python experiments/tgst_bandai/oracle_swap.py WORKDIR EVAL_DIR OUT_JSON [--trim 0.3] [--pairs intra,inter]
        [--temperatures 0.25,1] [--max-pairs 0]

For every held-out content/style pair (as `jaxgest tgst evaluate` builds them) the content and the style clip are
encoded by the workdir's autoencoder exactly as a transfer does (`model.encode_pair`), tokenized (eq. 1) and the
content tokens are replaced by style tokens chosen by an ORACLE instead of the learned similarity; the result is
cross-faded (`tokens.detokenize`), decoded, written on the content's rig (`TGSTModel.to_motion`) and scored under
the authors' protocol (`protocol.features_errors`). Variants (method names in the JSON):

* ``learned_soft`` / ``learned_hard``: the workdir's transformer (eq. 4 / eq. 19), same pipeline (reference).
* ``oracle_latent_hard``: each content token -> the style token nearest in latent token space (L2, 64-d).
* ``oracle_latent_soft_T``: softmax(-d^2 / (T * median_n min_m d^2)) over style tokens (T = temperatures):
  the cost of blending (averaging) tokens rather than picking one.
* ``oracle_hands_hard``: each content token -> the style token whose 16 frames of root-local hand positions
  are nearest to the content's (what a perfect content similarity could pick, in the metric's own space).
* ``oracle_latent_frame``: each content LATENT FRAME (4 motion frames) -> the nearest style latent frame, no
  tokens, no cross-fade: the finest collage (token length).
* ``oracle_hands_frame``: the same per latent frame, chosen by the frame's 4 frames of hand positions.
* ``style_roundtrip``: the style clip through the autoencoder (scored against the content clip; its style
  error is the floor of any collage of its tokens); ``content_roundtrip``: the content's own tokens
  (= the autoencoder round trip).
* ``style_as_is`` / ``content_as_is``: the dataset clips themselves (controls).

Besides the errors, per variant: ``token_dist`` = mean over content tokens of ||g^c_n - g^{s|c}_n|| (latent
token distance from the content token it replaces) and, for ``random_token``, the same for a uniformly random
style token (chance level).
"""
import argparse
import json
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest import metrics
from jaxgest.runtime.errors import DataError
from jaxgest.motion import body, kinematics
from jaxgest.motion.datasets import load_folder, resample_motion
from jaxgest.tgst import model as M
from jaxgest.tgst import swap
from jaxgest.tgst.api import load_model
from jaxgest.tgst.evaluate import make_pairs
from jaxgest.tgst.protocol import clip_features, features_errors, get_protocol
from jaxgest.tgst.tokens import detokenize, tokenize


def hands_60(motion, fps):
    """Root-local hand positions (F, 6) in metres at the model rate."""
    m = resample_motion(motion, fps) if abs(motion.fps - fps) > 1e-9 else motion
    pos = kinematics.root_local_positions(m)
    return metrics.hands_metres(pos, body.joint_indices(m.skeleton, body.HANDS))


def frame_windows(h, start_frames, length):
    """(N, length*6) windows of hand frames h (F, 6) starting at each start (edge-padded at both ends)."""
    lo = max(0, -int(min(start_frames)))
    hi = max(0, int(max(start_frames)) + length - len(h))
    hp = np.pad(h, ((lo, hi), (0, 0)), mode="edge")
    return np.stack([hp[s + lo:s + lo + length].reshape(-1) for s in start_frames])


def nearest(a, b):
    """argmin_m ||a_n - b_m||^2 and the squared distances (N, M)."""
    d2 = (a * a).sum(1)[:, None] + (b * b).sum(1)[None] - 2 * a @ b.T
    return np.argmin(d2, 1), np.maximum(d2, 0)


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("workdir"), ap.add_argument("eval_dir"), ap.add_argument("out")
    ap.add_argument("--trim", type=float, default=0.3)
    ap.add_argument("--pairs", default="intra,inter")
    ap.add_argument("--temperatures", default="0.25,1")
    ap.add_argument("--max-pairs", type=int, default=0)
    a = ap.parse_args(argv[1:])
    temps = [float(t) for t in a.temperatures.split(",") if t]
    model = load_model(a.workdir)
    cfg, params = model.cfg, model.params
    red, w, h = cfg.autoencoder.time_reduction, cfg.token_width, cfg.token_stride
    proto = get_protocol("authors", a.trim)
    clips = load_folder(a.eval_dir)
    enc = jax.jit(M.encode_pair, static_argnames="cfg")
    dec = jax.jit(M.decode, static_argnames="cfg")
    tr = jax.jit(M.transfer_tokens, static_argnames=("cfg", "hard"))
    report = {"workdir": a.workdir, "protocol": proto.describe(), "temperatures": temps, "pairs": {}}
    t0 = time.perf_counter()
    for mode in a.pairs.split(","):
        pairs = make_pairs(clips, mode, max_pairs=a.max_pairs or None)
        records = []
        for p in pairs:
            fps = p.content.motion.fps
            window = metrics.window_for_fps(fps)
            try:
                c_feats, s_ref = clip_features(p.content.motion, fps, proto), clip_features(p.style.motion, fps, proto, reference=True)
                s_plain = clip_features(p.style.motion, fps, proto)
            except Exception as e:  # too short for the cut
                records.append({"content": str(p.content.path), "style": str(p.style.path), "skipped": str(e)})
                continue
            if len(s_ref[1]) < window or len(c_feats[1]) < window:
                records.append({"content": str(p.content.path), "style": str(p.style.path), "skipped": "short"})
                continue
            cu = model.body_arrays(p.content.motion, "content")
            su = model.body_arrays(p.style.motion, "style")
            fc, fs = len(cu), len(su)
            zc, zs, c_range, _ = enc(params["autoencoder"], cu[None], su[None], cfg=cfg)
            tc, ts = tokenize(zc, w, h), tokenize(zs, w, h)
            gc, gs = np.asarray(tc[0]), np.asarray(ts[0])
            nc, ns = len(gc), len(gs)
            # hands at the model rate, windows aligned with the tokens (content: padded layout, lead = edge frames)
            hc, hs = hands_60(p.content.motion, cfg.fps), hands_60(p.style.motion, cfg.fps)
            lead = cfg.edge_frames
            tok_len = w * red
            c_starts = [n * h * red - lead for n in range(nc)]
            s_starts = [m * h * red for m in range(ns)]
            hw_c, hw_s = frame_windows(hc, c_starts, tok_len), frame_windows(hs, s_starts, tok_len)
            zc_np, zs_np = np.asarray(zc[0]), np.asarray(zs[0])
            hf_c = frame_windows(hc, [k * red - lead for k in range(len(zc_np))], red)
            hf_s = frame_windows(hs, [k * red for k in range(len(zs_np))], red)

            variants = {}  # name -> latents (Tc, 16)
            token_choice = {}  # name -> swapped tokens (nc, 64) for the token distance

            def from_weights(name, wts):
                toks = np.asarray(wts, np.float32) @ gs
                token_choice[name] = toks
                variants[name] = detokenize(jnp.asarray(toks)[None], zc.shape[1], w, h)

            for hard in (False, True):
                toks, aux = tr(params["transformer"], tc, ts, cfg=cfg, hard=hard)
                name = "learned_hard" if hard else "learned_soft"
                token_choice[name] = np.asarray(toks[0])
                variants[name] = detokenize(toks, zc.shape[1], w, h)
            idx, d2 = nearest(gc, gs)
            from_weights("oracle_latent_hard", np.eye(ns)[idx])
            scale = float(np.median(d2.min(1))) + 1e-9
            for t in temps:
                logits = -d2 / (t * scale)
                wts = np.exp(logits - logits.max(1, keepdims=True))
                from_weights(f"oracle_latent_soft_{t:g}", wts / wts.sum(1, keepdims=True))
            idx_h, _ = nearest(hw_c, hw_s)
            from_weights("oracle_hands_hard", np.eye(ns)[idx_h])
            fidx, _ = nearest(zc_np, zs_np)
            variants["oracle_latent_frame"] = jnp.asarray(zs_np[fidx])[None]
            fidx_h, _ = nearest(hf_c, hf_s)
            variants["oracle_hands_frame"] = jnp.asarray(zs_np[fidx_h])[None]
            variants["content_roundtrip"] = zc
            rng = np.random.default_rng(0)
            token_choice["random_token"] = gs[rng.integers(0, ns, nc)]

            rec = {"content": str(p.content.path), "style": str(p.style.path), "nc": nc, "ns": ns,
                   "errors": {}, "token_dist": {}}
            for name, toks in token_choice.items():
                rec["token_dist"][name] = float(np.mean(np.linalg.norm(toks - gc, axis=1)))
            real = slice(c_range[0] // h, c_range[0] // h + max(1, (c_range[1] - c_range[0] - w) // h + 1))
            rec["hands_dist_per_token"] = {  # mean hand distance (m, per frame) of the chosen style tokens
                nm: float(np.mean(np.linalg.norm((hw_c[real] - hw_s[i][real]).reshape(-1, 6), axis=1)))
                for nm, i in (("oracle_latent_hard", idx), ("oracle_hands_hard", idx_h))}
            def score(feats):
                try:
                    return features_errors(feats, c_feats, s_ref, window=window)
                except DataError as e:  # a result shorter than one style window (the style clip's own frames)
                    return {"skipped": str(e)}

            for name, z in variants.items():
                up, lo = dec(params["autoencoder"], z, cfg=cfg)
                up, lo = M.trim_clip(up, fc, cfg=cfg), M.trim_clip(lo, fc, cfg=cfg)
                out = model.to_motion(np.asarray(up[0]), np.asarray(lo[0]), p.content.motion)
                rec["errors"][name] = score(clip_features(out, fps, proto))
            # style clip through the autoencoder round trip, on its own rig and frames
            up, lo = M.reconstruct(params["autoencoder"], jnp.asarray(su)[None], cfg=cfg)
            out = model.to_motion(np.asarray(up[0]), np.asarray(lo[0]), p.style.motion)
            rec["errors"]["style_roundtrip"] = score(clip_features(out, fps, proto))
            rec["errors"]["style_as_is"] = score(s_plain)
            rec["errors"]["content_as_is"] = score(c_feats)
            records.append(rec)
            print(mode, len(records), f"{time.perf_counter() - t0:.0f}s",
                  {k: round(v["content"]["mean"], 3) for k, v in rec["errors"].items() if "content" in v}, flush=True)
        done = [r for r in records if "errors" in r]
        names = list(done[0]["errors"]) if done else []
        summary = {}
        for nm in names:
            ok = [r for r in done if "content" in r["errors"][nm]]
            ce = np.array([r["errors"][nm]["content"]["mean"] for r in ok])
            se = np.array([r["errors"][nm]["style"]["mean"] for r in ok])
            summary[nm] = {"content": float(ce.mean()), "style": float(se.mean()), "n": len(ok)}
        dist = {nm: float(np.mean([r["token_dist"][nm] for r in done])) for nm in (done[0]["token_dist"] if done else [])}
        report["pairs"][mode] = {"summary": summary, "token_dist": dist, "per_pair": records}
    report["wall_s"] = time.perf_counter() - t0
    with open(a.out, "w") as f:
        json.dump(report, f, indent=1)
    for mode, r in report["pairs"].items():
        print(mode)
        for nm, s in r["summary"].items():
            print(f"  {nm:24s} content {s['content']:.3f}  style {s['style']:.3f}  (n={s['n']})")
        print("  token_dist", {k: round(v, 3) for k, v in r["token_dist"].items()})


if __name__ == "__main__":
    main(sys.argv)

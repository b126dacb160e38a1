"""Issue 36 diagnostic (retired once run; its numbers are in the README): why the inter transfer does not take
the ground truth's arm-velocity style. python experiments/tgst_bandai2/diagnose_collage.py full_s0 4
(every 4th inter test pair, exemplar + mirror): soft / hard, the exemplar and its round trip, and collages
of the exemplar's tokens chosen by hand positions: nearest, DTW, constant rate, linear in time."""
import sys, json, numpy as np, jax.numpy as jnp
from jaxgest.motion import datasets, body, kinematics
from jaxgest.motion.datasets import resample_motion, Clip
from jaxgest import metrics
from jaxgest.tgst import multitake as mt, multitake_eval as me, model as M
from jaxgest.tgst.api import load_model
from jaxgest.tgst.tokens import detokenize, tokenize
from jaxgest.tgst.protocol import clip_features, style_reference

run = sys.argv[1]; every = int(sys.argv[2]) if len(sys.argv) > 2 else 2
model = load_model(f"experiments/tgst_bandai2/out/runs/{run}")
clips = datasets.load_folder("../shared/data/bandai-namco-2")
pairs = [p for p in mt.make_multitake_pairs(clips, exemplar_takes=1) if p.condition != "intra"][::every]
proto = me.multitake_protocol()
cfg, params = model.cfg, model.params
red, w, h, lead = cfg.autoencoder.time_reduction, cfg.token_width, cfg.token_stride, cfg.edge_frames

def hands(m):
    m = resample_motion(m, cfg.fps)
    return metrics.hands_metres(kinematics.root_local_positions(m), body.joint_indices(m.skeleton, body.HANDS))

def windows(x, starts, length):
    lo, hi = max(0, -min(starts)), max(0, max(starts) + length - len(x))
    xp = np.pad(x, ((lo, hi), (0, 0)), mode="edge")
    return np.stack([xp[s + lo:s + lo + length].reshape(-1) for s in starts])

def subseq_dtw(d, max_step=2):
    N, Mm = d.shape; D = np.full((N, Mm), np.inf); B = np.zeros((N, Mm), int)
    D[0] = d[0]
    for n in range(1, N):
        for k in range(max_step + 1):
            prev = np.full(Mm, np.inf); prev[k:] = D[n - 1, :Mm - k] if k else D[n - 1]
            better = prev < D[n] - d[n] if k else np.ones(Mm, bool)
            if k == 0:
                D[n] = d[n] + prev; B[n] = 0
            else:
                m = prev + d[n] < D[n]; D[n][m] = (prev + d[n])[m]; B[n][m] = k
    idx = np.zeros(N, int); idx[-1] = int(np.argmin(D[-1]))
    for n in range(N - 1, 0, -1):
        idx[n - 1] = idx[n] - B[n, idx[n]]
    return idx

def collage(cmot, smot, choose):
    cu, su = model.body_arrays(cmot, "content"), model.body_arrays(smot, "style")
    zc, zs, _, _ = M.encode_pair(params["autoencoder"], jnp.asarray(cu)[None], jnp.asarray(su)[None], cfg=cfg)
    tc, ts = np.asarray(tokenize(zc, w, h)[0]), np.asarray(tokenize(zs, w, h)[0])
    hc = windows(hands(cmot), [n * h * red - lead for n in range(len(tc))], w * red)
    hs = windows(hands(smot), [m * h * red for m in range(len(ts))], w * red)
    d2 = (hc * hc).sum(1)[:, None] + (hs * hs).sum(1)[None] - 2 * hc @ hs.T
    idx = choose(np.sqrt(np.maximum(d2, 0)), len(tc), len(ts))
    z = detokenize(jnp.asarray(ts[idx])[None], zc.shape[1], w, h)
    up, lo = M.decode(params["autoencoder"], z, cfg=cfg)
    up, lo = M.trim_clip(up, len(cu), cfg=cfg), M.trim_clip(lo, len(cu), cfg=cfg)
    return model.to_motion(np.asarray(up[0]), np.asarray(lo[0]), cmot), idx

def hard_idx(cmot, smot):
    cu, su = model.body_arrays(cmot, "content"), model.body_arrays(smot, "style")
    W = np.asarray(M.swap_weights(params, jnp.asarray(cu)[None], jnp.asarray(su)[None], cfg=cfg)[0])
    return W

choosers = {
    "oracle": lambda d, N, Mm: d.argmin(1),
    "dtw": lambda d, N, Mm: subseq_dtw(d),
    "linear": lambda d, N, Mm: np.round(np.linspace(0, Mm - 1, N)).astype(int),
    "rate": lambda d, N, Mm: const_rate(d),
}
def const_rate(d):
    N, Mm = d.shape; best = (np.inf, None)
    for r in np.arange(0.5, 2.01, 0.05):
        for s0 in range(Mm):
            idx = np.round(s0 + r * np.arange(N)).astype(int)
            if idx[-1] > Mm - 1 + 1: break
            idx = np.minimum(idx, Mm - 1)
            c = d[np.arange(N), idx].mean()
            if c < best[0]: best = (c, idx)
    if best[1] is None: return np.minimum(np.arange(N), Mm - 1)
    return best[1]
from jaxgest.tgst.batched import BatchedTransfer
bt = BatchedTransfer(model, ("soft", "hard", "autoencoder"), diagnostics=True)
rows = []
for i, p in enumerate(pairs):
    fps = p.content.motion.fps
    feats = me.FeatureCache(proto, fps); win = me.window_frames(fps)
    try:
        c, e_ref = feats(p.content), feats(p.exemplar, True)
        gts = [(feats(g), feats(g, True)) for g in p.ground_truths]
    except Exception as err:
        continue
    plain = lambda m: clip_features(m, fps, proto)
    mir = Clip(style_reference(p.exemplar.motion, proto), p.exemplar.content, p.exemplar.style, p.exemplar.path)
    outs, diag = bt.run(me._Run(p.content, mir))
    ex_rt = bt.run(me._Run(p.exemplar, p.exemplar))[0]["autoencoder"]
    res = {"condition": p.condition, "style": p.style, "diag": diag}
    cu_, su_ = model.body_arrays(p.content.motion, "content"), model.body_arrays(mir.motion, "style")
    W = np.asarray(M.swap_weights(params, jnp.asarray(cu_)[None], jnp.asarray(su_)[None], cfg=cfg)[0])
    am = W.argmax(1); st = np.diff(am)
    res["hard_steps"] = {"one": float(np.mean(st == 1)), "zero": float(np.mean(st == 0)), "far": float(np.mean(np.abs(st) > 2)), "back": float(np.mean(st < 0))}
    cand = {"soft": plain(outs["soft"]), "hard": plain(outs["hard"]), "content": c,
            "exemplar": feats(p.exemplar), "exemplar_rt": plain(ex_rt)}
    for name, ch in choosers.items():
        mot, idx = collage(p.content.motion, mir.motion if name != "linear" else p.exemplar.motion, ch)
        cand[f"collage_{name}"] = plain(mot)
        if name == "dtw": res["dtw_idx"] = idx.tolist()
    for name, f in cand.items():
        try:
            e = me.errors_against(f, c, e_ref, gts, window=win)
        except Exception as err:
            e = {"skipped": str(err)}
        e["speed"] = me.arm_speed(f[1])
        res[name] = e
    res["gt_speed"] = float(np.mean([me.arm_speed(g[0][1]) for g in gts]))
    rows.append(res)
    print(i, p.condition, p.style, {k: (round(res[k].get("gt_style", -1) or -1, 2), round(res[k]["speed"], 2)) for k in cand}, round(res["gt_speed"], 2), flush=True)
json.dump(rows, open(f"experiments/tgst_bandai2/out/diagnose_collage_{run}.json", "w"))

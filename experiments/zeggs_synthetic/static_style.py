"""Which part of the model carries a style's static pose: the style embedding or the initial pose?

    python experiments/zeggs_synthetic/static_style.py --workdir W --data D [--data D2 ...] [--frames 480] [--json OUT]

At inference the generator starts from the first frame of the style example (``TrainedZeggs.generate``;
the official ``generate.py`` does the same) and in training from the target window's own first frame. The
synthetic styles differ partly in *static* offsets (lean, head pitch, hand height; module table of
``jaxgest.motion.synthetic.styles``), which that first frame already shows. Two measurements:

1. **Crossed generation** (first ``--data`` folder): for every content c and ordered style pair (A, B),
   the motion generated from c's speech with the embedding (posterior mean) of clip (c, A) and the initial
   pose of clip (c, B). Per output, its static part (per-channel mean over frames 30.. of the normalised
   pose features) and dynamic part (per-channel std over those frames), also over each half of them. For A != B the position of the crossed output
   between the matched outputs (A, A) and (B, B): t = <x(A,B) - x(B,B), x(A,A) - x(B,B)> / |x(A,A) - x(B,B)|^2
   (1: follows the embedding, 0: follows the initial pose); mean +- SE over (c, A, B).
2. **Probe feature sets** on the leave-one-content-out folds of ``jaxgest zeggs evaluate`` (2 s windows
   every 0.5 s, ridge probe; all ``--data`` folders pooled): the embedding, the raw statistics, their
   means / stds alone, the window's first frame (what the generator's initializer sees), and the
   embedding with the first frame; per-style recall.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def crossed(model, clips, frames: int) -> dict:
    import jax.numpy as jnp

    from jaxgest.motion.datasets import load_clip_audio

    styles = sorted({c.style for c in clips})
    by = {(c.content, c.style): c for c in clips}
    rows = {}
    per_pair = {}
    for content in sorted({c.content for c in clips}):
        cs = [by[(content, s)] for s in styles if (content, s) in by]
        if len(cs) < 2:
            continue
        audio, sr = load_clip_audio(cs[0])
        speech, _ = model.speech(audio, sr=sr)
        speech = speech[:frames]
        s_emb = model.encode_speech(model.params, jnp.asarray(speech)[None])
        mus = [model.style_posterior(c.motion)[0] for c in cs]
        firsts = [model.pose_features(c.motion)[:1] for c in cs]
        pairs = [(a, b) for a in range(len(cs)) for b in range(len(cs))]
        n = len(pairs)
        out = model.run_generator(
            model.params, jnp.broadcast_to(s_emb, (n,) + s_emb.shape[1:]),
            jnp.asarray(np.stack([mus[a] for a, _ in pairs])), jnp.asarray(np.concatenate([firsts[b] for _, b in pairs])),
            jnp.zeros((n, 3), jnp.float32), jnp.tile(jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32), (n, 1)),
            jnp.tile(jnp.asarray([[0.0, 0.0, 1.0]], jnp.float32), (n, 1)), model.pose_mean, model.pose_std)
        pose = np.asarray(out["pose"], np.float64)
        half = 30 + (pose.shape[1] - 30) // 2  # skip the first half second (the start itself)
        feats = {"static": pose[:, 30:].mean(1), "dynamic": pose[:, 30:].std(1),
                 "static, first half": pose[:, 30:half].mean(1), "static, second half": pose[:, half:].mean(1),
                 "dynamic, first half": pose[:, 30:half].std(1), "dynamic, second half": pose[:, half:].std(1)}
        idx = {p: k for k, p in enumerate(pairs)}
        for kind, x in feats.items():
            for a, b in pairs:
                if a == b:
                    continue
                d = x[idx[(a, a)]] - x[idx[(b, b)]]
                t = float((x[idx[(a, b)]] - x[idx[(b, b)]]) @ d / max(d @ d, 1e-12))
                rows.setdefault(kind, []).append(t)
                per_pair.setdefault(kind, {}).setdefault(f"{cs[a].style}<-{cs[b].style}", []).append(t)
    res = {}
    for kind, ts in rows.items():
        ts = np.asarray(ts)
        res[kind] = {"mean": float(ts.mean()), "se": float(ts.std(ddof=1) / np.sqrt(len(ts))), "n": int(len(ts)),
                     "by_pair": {k: float(np.mean(v)) for k, v in sorted(per_pair[kind].items())}}
    return res


def probe_sets(model, clips) -> dict:
    from jaxgest.zeggs import probes as P

    xs = [P._windows(model, c, P.PROBE_WINDOW_S, P.PROBE_STRIDE_S) for c in clips]
    emb = P.encode_windows(model, xs)
    # the generator's initial pose of each window: its first frame in the output normalisation
    firsts = []
    fps = model.cfg.model.fps
    for c, x in zip(clips, xs):
        pf = model.pose_features(c.motion)
        n, stride = x.shape[1], max(1, int(P.PROBE_STRIDE_S * fps))
        starts = P._window_starts(len(pf), n, stride)
        firsts.append(pf[starts])
    sets = {
        "embedding (posterior mean)": emb,
        "raw statistics (means + stds)": [np.concatenate([x.mean(1), x.std(1)], 1) for x in xs],
        "raw means": [x.mean(1) for x in xs],
        "raw stds": [x.std(1) for x in xs],
        "first frame of the window (initial pose)": firsts,
        "embedding + first frame": [np.concatenate([e, f], 1) for e, f in zip(emb, firsts)],
    }
    styles, contents = [c.style for c in clips], [c.content for c in clips]
    names = sorted(set(styles))
    out = {}
    for name, feats in sets.items():
        r = P.grouped_probe(feats, styles, contents)
        # per-style recall (clip means within each style)
        pc = np.asarray(r["per_clip"])
        out[name] = {"accuracy": r["accuracy"], "clip_mean": r["clip_mean"],
                     "recall": {s: float(pc[[i for i, t in enumerate(styles) if t == s]].mean()) for s in names},
                     "per_clip": r["per_clip"]}
    base = np.asarray(out["raw statistics (means + stds)"]["per_clip"])
    for name in out:
        d = np.asarray(out[name].pop("per_clip")) - base
        out[name]["minus_raw"] = {"mean": float(d.mean()), "se": float(d.std(ddof=1) / np.sqrt(len(d)))}
    return out


def main(argv=None) -> int:
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs.inference import load_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--data", action="append", required=True)
    ap.add_argument("--frames", type=int, default=480)
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    model = load_model(a.workdir)
    first = load_folder(a.data[0])
    res = {"workdir": a.workdir, "data": a.data, "crossed": crossed(model, first, a.frames)}
    for kind, r in res["crossed"].items():
        print(f"crossed generation, {kind}: t = {r['mean']:.3f} +- {r['se']:.3f} (n {r['n']}; 1 = follows the "
              f"embedding, 0 = the initial pose)")
    clips = [c for d in a.data for c in load_folder(d)]
    res["probe"] = probe_sets(model, clips)
    names = sorted({c.style for c in clips})
    print(f"probes over {len(clips)} clips; recall per style: {', '.join(names)}")
    for name, r in res["probe"].items():
        print(f"  {name:42s} {r['accuracy']:.3f}  - raw {r['minus_raw']['mean']:+.3f} +- {r['minus_raw']['se']:.3f}  "
              + " ".join(f"{r['recall'][s]:.2f}" for s in names))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

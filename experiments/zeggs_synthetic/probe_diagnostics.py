"""Why raw window statistics beat the learned style embedding in the leave-one-content-out style probe.

On pooled synthetic datasets (folders of ``jaxgest synth --seed K``), the style probe of
:mod:`jaxgest.zeggs.probes` (leave-one-content-out over the pooled clips, per-clip accuracies, 95 % CI over
clips, paired differences over clips) for feature variants of one trained model, all on the same folds:

* the trained encoder's posterior mean (the probe's default) vs a posterior sample, vs mean and log-variance;
* windows of 1, 2 (default), 4 and 8 s (every 0.5 s);
* the raw-statistics control (window mean + std of the normalised pose features, 2P dims) as is, its means
  only, its stds only, and reduced to D_e dims by a PCA fitted on each fold's training windows (the
  embedding's dimension);
* the embedding and the raw statistics concatenated (does the embedding add anything to them?).

Usage: python experiments/zeggs_synthetic/probe_diagnostics.py --workdir W --data D1 D2 ... --json OUT.json
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np


def _pca_probe(features, labels, groups, dims: int) -> np.ndarray:
    """Per-clip accuracies of the leave-one-group-out probe on features reduced to ``dims`` principal
    components fitted on each fold's training windows only (standardised first, as the probe does)."""
    from jaxgest import metrics
    from jaxgest.zeggs import probes

    per_clip = np.zeros(len(features))
    for _, train, test in probes.probe_folds(groups):
        xtr = np.concatenate([features[i] for i in train]).astype(np.float64)
        ytr = np.concatenate([[labels[i]] * len(features[i]) for i in train])
        mu, sd = xtr.mean(0), np.maximum(xtr.std(0), 1e-8)
        _, _, vt = np.linalg.svd((xtr - mu) / sd, full_matrices=False)
        proj = vt[:dims].T
        xte = np.concatenate([features[i] for i in test])
        pred = metrics.linear_probe_predict(((xtr - mu) / sd) @ proj, ytr, ((xte - mu) / sd) @ proj)
        k = 0
        for i in test:
            n = len(features[i])
            per_clip[i] = np.mean([p == labels[i] for p in pred[k:k + n]])
            k += n
    return per_clip


def main(argv=None) -> int:
    from tqdm.auto import tqdm

    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import probes
    from jaxgest.zeggs.inference import load_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--data", nargs="+", required=True, help="dataset folders, pooled")
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0, help="seed of the posterior samples")
    args = ap.parse_args(argv)

    model = load_model(args.workdir)
    clips, units = [], []
    for d in args.data:
        cs = load_folder(d)
        clips += cs
        units += [str(d)] * len(cs)
    styles, contents = [c.style for c in clips], [c.content for c in clips]
    rng = np.random.default_rng(args.seed)
    de = model.cfg.model.style_embedding
    feats: dict[str, list] = {}
    fe = [model.style_features(c.motion) for c in tqdm(clips, desc="pose features", leave=False)]
    fps = model.cfg.model.fps
    stride = int(probes.PROBE_STRIDE_S * fps)
    for w in (1.0, 2.0, 4.0, 8.0):
        n = max(int(w * fps), model.cfg.model.style_min_frames)  # as probes._windows
        xs = [np.stack([f[s:s + n] for s in probes._window_starts(len(f), n, stride)]) for f in fe]
        mus, logvars = probes.encode_windows(model, xs, with_logvar=True)
        for x, mu, logvar in zip(xs, mus, logvars):
            mu, logvar = np.asarray(mu, np.float64), np.asarray(logvar, np.float64)
            raw = np.concatenate([x.mean(1), x.std(1)], axis=1)
            feats.setdefault(f"posterior mean, {w:g} s", []).append(mu)
            feats.setdefault(f"raw statistics, {w:g} s", []).append(raw)
            if w == 2.0:
                feats.setdefault("posterior sample, 2 s", []).append(
                    mu + np.exp(0.5 * logvar) * rng.standard_normal(mu.shape))
                feats.setdefault("posterior mean + log-variance, 2 s", []).append(np.concatenate([mu, logvar], 1))
                p = x.shape[2]
                feats.setdefault("raw means only, 2 s", []).append(raw[:, :p])
                feats.setdefault("raw stds only, 2 s", []).append(raw[:, p:])
                feats.setdefault("posterior mean + raw statistics, 2 s", []).append(np.concatenate([mu, raw], 1))
    per_clip = {name: np.asarray(probes.grouped_probe(f, styles, contents)["per_clip"]) for name, f in feats.items()}
    per_clip[f"raw statistics, 2 s, PCA to {de} dims (fitted per fold)"] = _pca_probe(
        feats["raw statistics, 2 s"], styles, contents, de)
    per_clip["posterior mean + raw statistics, 2 s"] = per_clip.pop("posterior mean + raw statistics, 2 s")
    dims = {name: int(f[0].shape[1]) for name, f in feats.items()}
    dims[f"raw statistics, 2 s, PCA to {de} dims (fitted per fold)"] = de
    base, raw = per_clip["posterior mean, 2 s"], per_clip["raw statistics, 2 s"]
    rows = {}
    for name, acc in per_clip.items():
        rows[name] = {"dims": dims[name], "style_probe": probes._mean_se(acc),
                      "minus_posterior_mean_2s": probes._mean_se(acc - base),
                      "minus_raw_statistics_2s": probes._mean_se(acc - raw)}
    out = {"workdir": str(args.workdir), "datasets": [str(d) for d in args.data], "clips": len(clips),
           "protocol": "style probe leave-one-content-out over the pooled clips; mean +- 95 % CI over clips; "
                       "differences paired per clip", "variants": rows}
    pathlib.Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    print(f"| features ({len(clips)} clips of {len(args.data)} datasets) | dims | style probe ± 95 % CI | "
          "− posterior mean 2 s | − raw statistics 2 s |\n|---|---:|---:|---:|---:|")
    for name, r in rows.items():
        s, a, b = r["style_probe"], r["minus_posterior_mean_2s"], r["minus_raw_statistics_2s"]
        print(f"| {name} | {r['dims']} | {s['mean']:.3f} ± {s['ci95_half_width']:.3f} | "
              f"{a['mean']:+.3f} ± {a['standard_error']:.3f} | {b['mean']:+.3f} ± {b['standard_error']:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

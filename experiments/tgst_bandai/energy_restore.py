"""Intervention behind "the blend damps the motion": the soft swap with its energy restored.

    python experiments/tgst_bandai/energy_restore.py EVAL_DIR OUT_PREFIX TRIM BASE_PREFIX WORKDIR... --seeds 0,1,2 [--alpha A]

Not a method of the paper: a diagnostic. The soft swap (eq. 4) as usual, then each latent channel's
deviation from its temporal mean (over the content's real latent frames) rescaled to the style clip's
temporal std of that channel (over its real frames): z' = mean(z) + (z - mean(z)) (std(z_s) / std(z))^A, with
A = 1 the variance half of AdaIN applied to the swapped latents (A = 0: the soft swap), mean and token choice
unchanged. Evaluated with
`jaxgest.tgst.evaluate.evaluate` (authors' protocol, TRIM-second cut) on intra and inter pairs; writes
OUT_PREFIX_{intra,inter}_s<k>.json (the method is stored as "soft") and prints, per pair averaged over the
seeds, the restored soft swap minus each method of BASE_PREFIX_{intra,inter}_s<k>.json (e.g. the tables'
`out/results/eval_fitmotion`) with standard errors over pairs.
"""
import argparse
import functools
import json
import sys

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.tgst import model as M
from jaxgest.tgst.api import load_model
from jaxgest.tgst.evaluate import evaluate
from jaxgest.runtime.training import write_json_atomic


@functools.partial(jax.jit, static_argnames=("cfg", "alpha"))
def restored_soft(params, cu, su, *, cfg, alpha=1.0):
    zc, zs, c_range, s_range = M.encode_pair(params["autoencoder"], cu, su, cfg=cfg)
    zx, _ = M.transfer_latents(params["transformer"], zc, zs, cfg=cfg, method="soft", content_valid=c_range,
                               style_valid=s_range)
    a, b = c_range
    real_x = zx[:, a:b]
    s0, s1 = s_range
    mu = real_x.mean(1, keepdims=True)
    gain = zs[:, s0:s1].std(1, keepdims=True) / (real_x.std(1, keepdims=True) + 1e-6)
    upper, lower = M.decode(params["autoencoder"], mu + (zx - mu) * gain ** alpha, cfg=cfg)
    fc = cu.shape[1]
    return M.trim_clip(upper, fc, cfg=cfg), M.trim_clip(lower, fc, cfg=cfg)


class Restored:
    """Any object with ``transfer(content, style, method)`` is a model for ``evaluate``; "soft" is replaced."""

    def __init__(self, model, alpha=1.0):
        self.model, self.alpha = model, alpha

    def transfer(self, content, style, method="soft", name=None, tolerance=None):
        m = self.model
        if method != "soft":
            return m.transfer(content, style, method=method, name=name, tolerance=tolerance)
        cu, su = m.body_arrays(content, "content"), m.body_arrays(style, "style")
        up, lo = restored_soft(m.params, cu[None], su[None], cfg=m.cfg, alpha=self.alpha)
        return m.to_motion(np.asarray(up[0]), np.asarray(lo[0]), content, tolerance=tolerance)


def style_means(report):
    return {(p["content"], p["style"]): {k: v["style"]["mean"] for k, v in p["errors"].items() if "style" in v}
            for p in report["per_pair"]}


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("eval_dir"), ap.add_argument("prefix"), ap.add_argument("trim", type=float)
    ap.add_argument("base"), ap.add_argument("workdirs", nargs="+"), ap.add_argument("--seeds", required=True)
    ap.add_argument("--alpha", type=float, default=1.0)
    a = ap.parse_args(argv[1:])
    seeds = a.seeds.split(",")
    for mode in ("intra", "inter"):
        new, base = [], []
        for seed, wd in zip(seeds, a.workdirs):
            path = f"{a.prefix}_{mode}_s{seed}.json"
            try:
                rep = json.load(open(path))
            except FileNotFoundError:
                rep = evaluate(wd, a.eval_dir, pairs=mode, methods=("soft",), model=Restored(load_model(wd), a.alpha),
                               progress=False, trim_seconds=a.trim)
                write_json_atomic(path, rep)
            new.append(style_means(rep))
            base.append(style_means(json.load(open(f"{a.base}_{mode}_s{seed}.json"))))
        keys = [k for k in new[0] if all(k in n and "soft" in n[k] for n in new)]
        restored = np.array([np.mean([n[k]["soft"] for n in new]) for k in keys])
        print(f"\n{mode}: restored soft swap {restored.mean():.3f} m/s over {len(keys)} pairs, {len(seeds)} seeds")
        for m in ("soft", "hard", "avatarnet", "adain"):
            other = np.array([np.mean([b[k][m] for b in base]) for k in keys])
            d = restored - other
            print(f"  minus {m:10s} ({other.mean():.3f}): {d.mean():+.3f} +- {d.std(ddof=1) / np.sqrt(len(d)):.3f}"
                  f" (restored lower on {int((d < 0).sum())}/{len(d)})")


if __name__ == "__main__":
    main(sys.argv)

"""Where the round trip's extra speed comes from: frame-to-frame change of the output by phase (frame mod 4).

    python experiments/tgst_bandai/ae_jitter.py WORKDIR STEP [WORKDIR STEP ...]

On the 30 held-out clips (out/ae_cache.npz of ae_cause.py), upper body exp-maps at the model rate, interior
frames: mean |x[t+1] - x[t]| of the output over the input (all 39 channels, and the 6 shoulder channels),
split by the phase t mod 4 of the transition (4 = the encoder's stride: t mod 4 == 3 crosses a latent
block boundary), for each workdir's autoencoder and for the block PCA-16 of the original + mirrored training
clips (the fit-pca starting point).
"""
import sys

import jax
import numpy as np

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from ae_cause import load_cache  # noqa: E402
from diagnose import load_params  # noqa: E402

from jaxgest.motion import body  # noqa: E402
from jaxgest.tgst import baselines  # noqa: E402
from jaxgest.tgst import model as tmodel  # noqa: E402

SHOULDERS = [3 * body.UPPER.index(n) + k for n in ("Shoulder_L", "Shoulder_R") for k in range(3)]


def phase_speed(outs, ins):
    """{'all': ratio, 'shoulders': ratio, 'by_phase': [ratio for t mod 4 = 0..3]} over interior frames."""
    num, den, nsh, dsh = np.zeros(4), np.zeros(4), np.zeros(4), np.zeros(4)
    for y, x in zip(outs, ins):
        dy, dx = np.abs(np.diff(y[16:-16], axis=0)), np.abs(np.diff(x[16:-16], axis=0))
        ph = (np.arange(16, 16 + len(dy))) % 4
        for p in range(4):
            num[p] += dy[ph == p].sum()
            den[p] += dx[ph == p].sum()
            nsh[p] += dy[ph == p][:, SHOULDERS].sum()
            dsh[p] += dx[ph == p][:, SHOULDERS].sum()
    return {"all": round(num.sum() / den.sum(), 3), "shoulders": round(nsh.sum() / dsh.sum(), 3),
            "by_phase": (num / den).round(3).tolist(), "shoulders_by_phase": (nsh / dsh).round(3).tolist()}


def main(args):
    data, held, _ = load_cache()
    ins = [u for u, _ in held if len(u) > 40]
    pca = baselines.block_pca_fit(data.upper + data.mirrored_upper, components=16, frames=4)
    print("pca16_mix", phase_speed([baselines.block_pca_reconstruct(pca, u) for u in ins], ins))
    for wd, step in zip(args[::2], args[1::2]):
        cfg, params = load_params(wd, int(step), transformer=False)
        rec = jax.jit(lambda p, u: tmodel.reconstruct(p, u, cfg=cfg)[0])
        outs = []
        for u in ins:
            f = len(u)
            up = np.concatenate([u, np.repeat(u[-1:], -f % 128, axis=0)])
            outs.append(np.asarray(rec(params["autoencoder"], up[None]))[0, :f])
        print(wd, step, phase_speed(outs, ins))


if __name__ == "__main__":
    main(sys.argv[1:])

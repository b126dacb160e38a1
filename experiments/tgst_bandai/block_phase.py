"""Is the autoencoder's residual arm noise tied to its 4-frame latent blocks? Round-trip error by frame phase.

    python experiments/tgst_bandai/block_phase.py WORKDIR EVAL_DIR [PERIOD]

Every clip of EVAL_DIR goes through the plain autoencoder round trip (`transfer --method autoencoder`);
the arm-joint velocities of input and output (authors' protocol, root-local, no cut, at the clips' own
30 fps) are grouped by i mod PERIOD (default 2: one 60-fps latent block of 4 frames is 2 frames at 30 fps,
so odd i are the velocities that cross a block boundary). Prints per phase the mean velocity error (m/s)
and the mean arm speed of input and output. Noise made at block boundaries would show as a larger error
and speed at one phase.
"""
import glob
import os
import sys

import numpy as np

from jaxgest.motion import bvh
from jaxgest.tgst.api import load_model
from jaxgest.tgst.protocol import clip_features, get_protocol


def main(workdir: str, eval_dir: str, period: int = 2) -> dict:
    proto = get_protocol("authors", 0.0)
    model = load_model(workdir)
    err, speed_in, speed_out, n = (np.zeros(period) for _ in range(4))
    for f in sorted(glob.glob(os.path.join(eval_dir, "*.bvh"))):
        motion = bvh.load(f)
        out = model.transfer(motion, motion, method="autoencoder")
        vi, vo = clip_features(motion, None, proto)[1], clip_features(out, None, proto)[1]
        k = min(len(vi), len(vo))
        vi, vo = vi[:k].reshape(k, -1, 3), vo[:k].reshape(k, -1, 3)
        e = np.linalg.norm(vo - vi, axis=-1).mean(1)
        si, so = np.linalg.norm(vi, axis=-1).mean(1), np.linalg.norm(vo, axis=-1).mean(1)
        phase = np.arange(k) % period
        for p in range(period):
            sel = phase == p
            err[p] += e[sel].sum(); speed_in[p] += si[sel].sum(); speed_out[p] += so[sel].sum(); n[p] += sel.sum()
    res = {"velocity_error": err / n, "speed_in": speed_in / n, "speed_out": speed_out / n}
    for k, v in res.items():
        print(f"{k:15s}", " ".join(f"{x:.4f}" for x in v))
    return res


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 2)

"""PCA-16 and mean-pose reconstruction baselines fitted on the ORIGINAL training clips only (no mirrored copies).

    python experiments/tgst_bandai/recon_baselines.py TRAIN_DIR EVAL_DIR OUT.json

Per-joint mean geodesic angle (degrees) on the held-out clips. diagnose.py reports the same baselines
beside the autoencoder (fitted on the original clips, and on the original + mirrored clips).
"""
import json
import sys

import numpy as np

from jaxgest.motion import body, datasets
from jaxgest.tgst import baselines
from jaxgest.tgst.data import motion_to_arrays


def main(argv):
    train_dir, eval_dir, out = argv[1:4]
    train = [motion_to_arrays(c.motion, 60.0)[0] for c in datasets.load_folder(train_dir, progress=False)]
    held = [motion_to_arrays(c.motion, 60.0)[0] for c in datasets.load_folder(eval_dir, progress=False)]
    pca = baselines.block_pca_fit(train, components=16, frames=4)
    mean_pose = baselines.mean_pose_fit(train)
    res = {}
    for name, fn in (("pca16", lambda u: baselines.block_pca_reconstruct(pca, u)), ("mean_pose", lambda u: mean_pose)):
        pj = np.mean([baselines.per_joint_angle_deg(fn(u), u) for u in held], axis=0)
        res[name] = {"mean": float(pj.mean()), "per_joint": dict(zip(body.UPPER, pj.round(3).tolist()))}
    json.dump({"fitted_on": "original training clips", **res}, open(out, "w"), indent=1)
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(sys.argv)

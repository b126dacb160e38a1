"""Is a mirrored clip in the representation of the originals? Per-joint statistics, old vs new mirror.

    python experiments/tgst_bandai/mirror_stats.py DATA_DIR OUT.json

For every clip of DATA_DIR (at the model rate, body representation as the autoencoder sees it: local
rotations of the 21 body joints, hips yaw removed) and its mirror by each method (``old``: reflections
inferred from rest offsets, the previous default; ``new``: :func:`jaxgest.tgst.data.mirror_motion`, the
rig's T-pose as the symmetric reference), per joint:

* ``mean_angle``: mean over frames of the local rotation's angle (deg), originals and mirrors;
* ``between_means``: angle (deg) between the chordal mean rotation of the originals' frames and of the
  mirrors' frames (all clips pooled): 0 when both live in the same region of rotation space;
* ``mirror_to_orig_mean``: mean over the mirrors' frames of the angle to the originals' mean rotation,
  beside ``orig_to_orig_mean`` (the originals' own spread about their mean);
* ``fk_max_cm``: max over clips/frames/joints of |FK(mirror) - reflect(FK(original))| with L/R swapped.
"""
import json
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from old_mirror import old_mirror  # noqa: E402

from jaxgest.motion import body, datasets, kinematics as K, rotations as R  # noqa: E402
from jaxgest.tgst.data import mirror_motion  # noqa: E402

FPS = 60.0


def chordal_mean(q):
    u, _, vt = np.linalg.svd(R.quat_to_matrix(q).mean(0))
    return R.matrix_to_quat(u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt)


def angle_deg(a, b):
    return np.degrees(R.quat_angle(R.quat_mul(R.quat_inv(a), b)))


def body_quats(motion):
    bc = body.motion_to_body(datasets.resample_motion(motion, FPS))
    e = np.concatenate([bc.upper.reshape(len(bc.upper), -1, 3), bc.lower.reshape(len(bc.lower), -1, 3)], 1)
    return R.expmap_to_quat(e)  # (F, 21, 4) in body.BODY order


def main(data_dir, out):
    clips = datasets.load_folder(data_dir, progress=False)
    methods = {"old": old_mirror, "new": mirror_motion}
    orig, mirrored, fk = [], {k: [] for k in methods}, {k: 0.0 for k in methods}
    for c in clips:
        m = c.motion
        orig.append(body_quats(m))
        p = K.forward_kinematics(m)
        reflected = p[:, K.mirror_pairs(m.skeleton)] * [-1, 1, 1]
        for k, f in methods.items():
            mm = f(m)
            fk[k] = max(fk[k], float(np.abs(K.forward_kinematics(mm) - reflected).max()))
            mirrored[k].append(body_quats(mm))
    qo = np.concatenate(orig)
    report = {"clips": len(clips), "frames": int(len(qo)), "fk_max_cm": fk, "joints": {}}
    for j, name in enumerate(body.BODY):
        mo = chordal_mean(qo[:, j])
        row = {"orig_mean_angle": float(np.degrees(R.quat_angle(qo[:, j])).mean()),
               "orig_to_orig_mean": float(angle_deg(mo, qo[:, j]).mean())}
        for k in methods:
            qm = np.concatenate(mirrored[k])[:, j]
            row[f"{k}_mean_angle"] = float(np.degrees(R.quat_angle(qm)).mean())
            row[f"{k}_between_means"] = float(angle_deg(mo, chordal_mean(qm)))
            row[f"{k}_mirror_to_orig_mean"] = float(angle_deg(mo, qm).mean())
        report["joints"][name] = row
    pathlib.Path(out).write_text(json.dumps(report, indent=1))
    print(f"{len(clips)} clips, {len(qo)} frames; FK max |mirror - reflected| (cm): old {fk['old']:.2e}, "
          f"new {fk['new']:.2e}")
    print(f"{'joint':12s} {'orig angle':>10s} {'old angle':>9s} {'new angle':>9s} | {'between means old':>17s} "
          f"{'new':>6s} | {'to orig mean: orig':>18s} {'old':>6s} {'new':>6s}")
    for name, r in report["joints"].items():
        print(f"{name:12s} {r['orig_mean_angle']:10.1f} {r['old_mean_angle']:9.1f} {r['new_mean_angle']:9.1f} | "
              f"{r['old_between_means']:17.1f} {r['new_between_means']:6.1f} | {r['orig_to_orig_mean']:18.1f} "
              f"{r['old_mirror_to_orig_mean']:6.1f} {r['new_mirror_to_orig_mean']:6.1f}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

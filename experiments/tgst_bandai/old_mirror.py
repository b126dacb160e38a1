"""The previous mirror (for comparison runs only): per-joint axis reflections inferred from the rest offsets,
ties resolved to the first axis, no T-pose. World positions are exact, but on Bandai-Namco the Neck, Head,
shoulders, arms and legs of a mirrored clip get local rotations ~100-180 deg from any original's.

    from old_mirror import old_mirror
"""
import numpy as np

from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton, mirror_pairs


def _reflection(axis: int) -> np.ndarray:
    m = np.eye(3)
    m[axis, axis] = -1.0
    return m


def old_mirror_frames(skeleton: Skeleton, axis: int = 0) -> np.ndarray:
    perm = mirror_pairs(skeleton)
    parents = skeleton.parents
    frames = np.empty((skeleton.num_joints, 3, 3))
    cands = [_reflection(a) for a in range(3)]
    for j in range(skeleton.num_joints):
        parent_frame = _reflection(axis) if parents[j] < 0 else frames[parents[j]]
        kids = [c for c in np.flatnonzero(parents == j) if np.linalg.norm(skeleton.offsets[c]) > 1e-6]
        if not kids:
            frames[j] = parent_frame
            continue
        src, dst = skeleton.offsets[kids], skeleton.offsets[perm[kids]]
        frames[j] = cands[int(np.argmin([np.abs(src @ m.T - dst).sum() for m in cands]))]
    return frames


def old_mirror(motion: Motion, axis: int = 0) -> Motion:
    sk = motion.skeleton
    perm, frames, world = mirror_pairs(sk), old_mirror_frames(sk, axis), _reflection(axis)
    mats = R.quat_to_matrix(motion.rotations)
    new_m, new_t = np.empty_like(mats), np.empty_like(motion.translations)
    for j in range(sk.num_joints):
        p = sk.parents[j]
        mp = world if p < 0 else frames[p]
        new_m[:, j] = mp @ mats[:, perm[j]] @ frames[j]
        if not any(c.endswith("position") for c in sk.channels[j]):
            new_t[:, j] = motion.translations[:, j]
        else:
            new_t[:, j] = motion.translations[:, perm[j]] @ mp.T
    return motion.replace(rotations=R.matrix_to_quat(new_m), translations=new_t)

"""Forward kinematics and velocities (docs/design.md §2); mirroring re-exported.

Also the pieces of the authors' evaluation protocol (docs/design.md §5): :func:`root_local_positions` (root at the
origin, root rotation reset), :func:`forward_differences` and :func:`append_motion` (the mirrored style clip
appended with a short slerp transition).

Motion-level functions take and return :class:`~jaxgest.motion.skeleton.Motion` and compute in NumPy
float64 (exact file-level numbers). :func:`fk_positions` is the batched ``jax.numpy`` version for use
inside jit (losses, features); its parent array is static.

docs/design.md §1 puts mirroring, yaw removal and floor contact here too; they live in
:mod:`jaxgest.motion.mirroring` (re-exported here) and :mod:`jaxgest.motion.root_motion` (a layer above:
it builds on this module's FK).
"""

from __future__ import annotations

import functools
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.motion import rotations as R
from jaxgest.motion.mirroring import mirror, mirror_frames  # noqa: F401 (re-exported)
from jaxgest.motion.skeleton import Motion, Skeleton, mirror_pairs, mirror_partner  # noqa: F401 (re-exported)

# ---------------------------------------------------------------------------------------------------
# The root joint

def _root_and_parent(skeleton: Skeleton, root: str | None):
    if root is None:
        root_idx = _hips_index(skeleton)
    else:
        root_idx = skeleton.index(root)
    return root_idx, int(skeleton.parents[root_idx])


def _hips_index(skeleton: Skeleton) -> int:
    """The hips: the first joint from the file root with more than one child (skips static wrappers)."""
    j = int(np.flatnonzero(skeleton.parents < 0)[0])
    while True:
        kids = np.flatnonzero(skeleton.parents == j)
        if len(kids) != 1:
            return j
        j = int(kids[0])


# ---------------------------------------------------------------------------------------------------
# Forward kinematics


def global_transforms(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """World rotations ``(F, J, 4)`` and positions ``(F, J, 3)`` of every joint, file order, file units.

    ``G_j = G_parent(j) * q_j`` and ``p_j = p_parent(j) + G_parent(j) t_j`` where ``t_j`` is the joint's
    local translation (position channels or rest offset).
    """
    parents = motion.skeleton.parents
    F, J = motion.rotations.shape[:2]
    grot = np.empty((F, J, 4))
    gpos = np.empty((F, J, 3))
    for j in range(J):
        p = parents[j]
        if p < 0:
            grot[:, j] = motion.rotations[:, j]
            gpos[:, j] = motion.translations[:, j]
        else:
            grot[:, j] = R.quat_mul(grot[:, p], motion.rotations[:, j])
            gpos[:, j] = gpos[:, p] + R.quat_rotate(grot[:, p], motion.translations[:, j])
    return grot, gpos


def forward_kinematics(motion: Motion) -> np.ndarray:
    """World positions ``(F, J, 3)`` of all J joints in file order (End Sites excluded), file units."""
    return global_transforms(motion)[1]


def global_rotations(motion: Motion) -> np.ndarray:
    """World rotations ``(F, J, 4)`` (w, x, y, z) of all joints in file order."""
    return global_transforms(motion)[0]


def root_local_positions(motion: Motion, root: str | None = None) -> np.ndarray:
    """Joint positions ``(F, J, 3)`` with the root at the origin and its rotation reset (file units).

    ``p'_j = G_root^-1 (p_j - p_root)``: forward kinematics with the root's translation zeroed and its world
    rotation set to the identity, i.e. every joint in the frame of the root. The root is the hips (the first
    joint below the file root with several children: ``Hips`` of Bandai-Namco, below its static
    ``joint_Root``, and of ZEGGS) unless ``root`` names another joint. Joints above the root get the same
    transform (they are static wrappers on both datasets).
    References: the authors' evaluator (``get_joint_positions(root_positions=None)`` in dataset/mocap.py:
    "We also reset orientation of root"); docs/design.md §5 (authors' protocol).
    """
    r, _ = _root_and_parent(motion.skeleton, root)
    grot, gpos = global_transforms(motion)
    inv = R.quat_inv(grot[:, r])[:, None, :]
    return R.quat_rotate(np.broadcast_to(inv, grot.shape), gpos - gpos[:, r : r + 1])


def fk_positions(rotations: jax.Array, translations: jax.Array, parents: Sequence[int]) -> jax.Array:
    """Batched jnp forward kinematics: ``(..., J, 4)``, ``(..., J, 3)`` -> world positions ``(..., J, 3)``.

    Same equations as :func:`global_transforms`. ``parents`` is static (a Python sequence, -1 for roots);
    joints are processed one tree *level* at a time (all joints of equal depth in one vectorised step), so
    the traced graph has depth-many steps (7 for the body, 12 for ZEGGS) instead of one per joint, which
    keeps jit compile times small. Usable inside jit and under grad.
    """
    levels, where = _fk_levels(tuple(int(p) for p in parents))
    grot = rotations[..., levels[0][0], :]
    gpos = translations[..., levels[0][0], :]
    out = [gpos]
    for idx, par in levels[1:]:
        gp, pp = grot[..., par, :], gpos[..., par, :]
        grot = R.quat_mul(gp, rotations[..., idx, :])
        gpos = pp + R.quat_rotate(gp, translations[..., idx, :])
        out.append(gpos)
    return jnp.concatenate(out, axis=-2)[..., where, :]


def fk_expmap_positions_joint_major(expmaps: jax.Array, offsets, parents: Sequence[int]) -> jax.Array:
    """:func:`fk_positions` of exp-map rotations with the joints leading: ``expmaps (J, ..., 3)``, constant bone
    ``offsets (J, 3)`` (NumPy; a root's offset is its position) -> world positions ``(J, ..., 3)``.

    The same equations (``G_j = G_parent(j) * q_j``, ``p_j = p_parent(j) + G_parent(j) t_j``, one tree level at a
    time), laid out for a training step: choosing a level's parents is a copy of whole rows. With the joints
    second to last (``fk_positions``) it is a strided gather, and a scatter-add in the backward pass: the TGST
    autoencoder step's displacement term ran ~4x slower that way (value and gradient, 32 x 256 frames).
    """
    levels, where = _fk_levels(tuple(int(p) for p in parents))
    offsets = np.asarray(offsets, np.float32)
    if expmaps.shape[0] != len(parents) or expmaps.shape[-1] != 3 or offsets.shape != (len(parents), 3):
        raise ValueError(f"expmaps must be (J, ..., 3) and offsets (J, 3) for J = {len(parents)}, got "
                         f"{expmaps.shape} and {offsets.shape}")
    q = R.expmap_to_quat(expmaps)
    lead = (1,) * (expmaps.ndim - 2)

    def bones(idx):  # the offsets of joints idx, broadcast over the frames
        return jnp.broadcast_to(jnp.asarray(offsets[idx]).reshape((len(idx),) + lead + (3,)),
                                (len(idx),) + expmaps.shape[1:])

    root = levels[0][0]
    grot, gpos = q[root], bones(root)
    out = [gpos]
    for idx, par in levels[1:]:
        parent_rot = grot[par]
        grot = R.quat_mul(parent_rot, q[idx])
        gpos = gpos[par] + R.quat_rotate(parent_rot, bones(idx))
        out.append(gpos)
    return jnp.concatenate(out, axis=0)[where]


@functools.lru_cache(maxsize=64)
def _fk_levels(parents: tuple) -> tuple[tuple, np.ndarray]:
    """Joints grouped by depth: ``((indices, parent positions within the previous level), ...)`` and the
    permutation from level order back to file order (memoised; every array read-only)."""
    depth = []
    for j, p in enumerate(parents):
        if p >= j:
            raise ValueError(f"parents must precede children (joint {j} has parent {p})")
        depth.append(0 if p < 0 else depth[p] + 1)
    depth = np.asarray(depth)
    levels, pos = [], {}
    for d in range(int(depth.max()) + 1):
        idx = np.flatnonzero(depth == d)
        par = np.array([pos[parents[j]] for j in idx]) if d else np.zeros(0, np.int64)
        levels.append((idx, par))
        pos = {int(j): i for i, j in enumerate(idx)}
    order = np.concatenate([idx for idx, _ in levels])
    inverse = np.argsort(order)
    for arr in [inverse, *(a for level in levels for a in level)]:
        arr.flags.writeable = False  # memoised and shared by every caller: read-only
    return tuple(levels), inverse


def joint_velocities(positions: np.ndarray, fps: float) -> np.ndarray:
    """Per-second joint velocities ``(F, ..., 3)`` by backward differences; frame 0 repeats frame 1."""
    positions = np.asarray(positions, np.float64)
    v = np.empty_like(positions)
    if len(positions) < 2:
        v[:] = 0.0
        return v
    v[1:] = (positions[1:] - positions[:-1]) * fps
    v[0] = v[1]
    return v


def forward_differences(positions: np.ndarray, fps: float) -> np.ndarray:
    """Per-second velocities ``(F - 1, ..., 3)``: ``v_t = (p_{t+1} - p_t) * fps`` for t = 0 .. F - 2.

    No frame is repeated or invented (unlike :func:`joint_velocities`), so every velocity is the exact
    displacement of one frame step: a constant-speed motion gives that speed at both ends.
    References: the authors' evaluator (``60. * (x[1:] - x[:-1])`` in evaluator.py); docs/design.md §5.
    """
    positions = np.asarray(positions, np.float64)
    if len(positions) < 2:
        raise DataError(f"forward differences need at least 2 frames, got {len(positions)}")
    return (positions[1:] - positions[:-1]) * float(fps)


def append_motion(first: Motion, second: Motion, transition: int = 0) -> Motion:
    """``first`` followed by ``second`` (same skeleton and rate), blended over ``transition`` frames.

    The last ``transition`` frames of ``first`` move linearly toward the first ``transition`` frames of
    ``second`` (slerp of rotations, lerp of translations, weight k / transition at the k-th of them), then
    ``second`` continues from its frame ``transition``: ``Fa + Fb - transition`` frames. ``transition`` is
    clamped to both lengths. Used to append the mirrored style clip as the authors' evaluator does
    (``MocapClip.append(mirrored, transit=True, period=30)`` at 60 fps).
    References: the authors' dataset/mocap.py (``add_mirror_motion``, ``append``); docs/design.md §5.
    """
    if first.skeleton.num_joints != second.skeleton.num_joints:
        raise DataError("append_motion: the clips have different skeletons")
    n = max(0, min(int(transition), first.num_frames, second.num_frames))
    rot_a, tr_a = first.rotations.copy(), first.translations.copy()
    if n:
        w = (np.arange(n) / n)[:, None]
        a_idx = slice(first.num_frames - n, first.num_frames)
        q_a, q_b = rot_a[a_idx], second.rotations[:n]
        rot_a[a_idx] = R.quat_slerp(q_a, q_b, np.broadcast_to(w, q_a.shape[:2]))
        tr_a[a_idx] = (1.0 - w[..., None]) * tr_a[a_idx] + w[..., None] * second.translations[:n]
    return first.replace(
        rotations=np.concatenate([rot_a, second.rotations[n:]]),
        translations=np.concatenate([tr_a, second.translations[n:]]),
    )

"""ZeroEGGS losses (eqs. 1-2): MAE reconstruction terms in root-frame ("local") and world space, KL.

Feature layout (per frame, ``P = 15 j + 6``, :class:`jaxgest.zeggs.features.PoseLayout`)::

    [ local positions 3j | local 2-axis rotations 6j | local velocities 3j | local angular velocities 3j
      | root velocity 3 | root angular velocity 3 ]

"Local" is the character-root frame (a ground-plane transform): positions and rotations relative to the
root; velocities are world velocities expressed in the root frame (as ``extract_features`` computes them).
World quantities apply the root transform: positions ``q p + r``, rotations ``q R`` (both 6-D columns
rotated), velocities ``q v``. The vertical axis is Y and the world forward +Z (both datasets).

With the rig in the model config (``fk_parents`` etc., set from the data by training), the position terms --
character frame ("local"), world, and their finite differences -- use joint positions by forward
kinematics of the predicted rotations (:func:`forward_kinematics`), the motion that is rendered, as the
authors' train.py computes its character/world terms; the predicted position channels keep a term of their
own (``predicted_position``) because the generator reads them back.

The paper names the terms (eq. 2) and says each is an MAE "in both local and world spaces" and that the
weights are chosen empirically; the authors' code adds root position / rotation / velocity terms and
divides the sum by 18 -- we keep every term, with the code's weights (``TrainConfig.w_*``), and say which
eq. 2 lambda each belongs to. Term functions return per-example means ``(batch,)``; the step reduces.

References: Ghorbani et al. 2023, §4.3, eqs. 1-2; Holden et al. 2020 (finite-difference velocity losses);
Bowman et al. 2016 (KL annealing).
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.motion import rotations
from jaxgest.zeggs.config import ModelConfig, TrainConfig

WORLD_FORWARD = (0.0, 0.0, 1.0)


def mae(pred: jax.Array, target: jax.Array, frame_weight: jax.Array | None = None) -> jax.Array:
    """Mean absolute error per example: ``(batch, T, ...) -> (batch,)``.

    ``frame_weight`` ``(batch, T)`` (optional): a weighted mean over frames of the per-frame means (all ones
    is the plain mean; a row whose weights are all zero gives 0).
    """
    chex.assert_equal_shape([pred, target])
    err = jnp.abs(pred - target)
    if frame_weight is None:
        return jnp.mean(err.reshape(pred.shape[0], -1), axis=1)
    chex.assert_shape(frame_weight, pred.shape[:2])
    per_frame = jnp.mean(err.reshape(pred.shape[:2] + (-1,)), axis=2)
    return jnp.sum(frame_weight * per_frame, 1) / jnp.maximum(jnp.sum(frame_weight, 1), 1e-8)


def finite_difference(x: jax.Array, fps: float) -> jax.Array:
    """Velocity by forward differences over frames: ``(batch, T, ...) -> (batch, T-1, ...)``."""
    return (x[:, 1:] - x[:, :-1]) * fps


def split_pose(pose: jax.Array, cfg: ModelConfig) -> dict[str, jax.Array]:
    """Denormalised pose features ``(batch, T, P)`` -> named parts (joints on their own axis)."""
    lay, j = cfg.layout, cfg.num_joints
    lead = pose.shape[:-1]
    return {
        "position": pose[..., lay.local_positions].reshape(lead + (j, 3)),
        "rotation": pose[..., lay.local_rotations].reshape(lead + (j, 6)),
        "velocity": pose[..., lay.local_velocities].reshape(lead + (j, 3)),
        "angular": pose[..., lay.local_angular_velocities].reshape(lead + (j, 3)),
        "root_velocity": pose[..., lay.root_velocity],
        "root_angular": pose[..., lay.root_angular_velocity],
    }


def to_world(parts: dict[str, jax.Array], root_position: jax.Array, root_rotation: jax.Array) -> dict:
    """World-space joint positions, 6-D rotations, velocities and angular velocities ``(batch, T, j, .)``.

    The root rotation becomes one matrix per frame, applied to all 5 vectors of every joint in a single
    product (mathematically ``quat_rotate``; far fewer XLA ops than five quaternion rotations).
    References: Ghorbani et al. 2023, §4.3 ("in both local and world spaces").
    """
    rot = parts["rotation"]
    vecs = jnp.stack([parts["position"], rot[..., :3], rot[..., 3:], parts["velocity"], parts["angular"]], -2)
    m = rotations.quat_to_matrix(root_rotation)  # (batch, T, 3, 3)
    w = jnp.einsum("btij,btkvj->btkvi", m, vecs)
    return {
        "position": w[..., 0, :] + root_position[..., None, :],
        "rotation": jnp.concatenate([w[..., 1, :], w[..., 2, :]], axis=-1),
        "velocity": w[..., 3, :],
        "angular": w[..., 4, :],
    }


def facing_direction(root_rotation: jax.Array) -> jax.Array:
    """World facing direction of the character root ``(batch, T, 3)`` (the root's forward axis)."""
    fwd = jnp.broadcast_to(jnp.asarray(WORLD_FORWARD, root_rotation.dtype), root_rotation.shape[:-1] + (3,))
    return rotations.quat_rotate(root_rotation, fwd)


def forward_kinematics(rotation: jax.Array, position: jax.Array, cfg: ModelConfig) -> jax.Array:
    """Root-frame joint positions ``(..., j, 3)`` by FK of root-frame 6-D rotations ``(..., j, 6)``.

    The rig comes from ``cfg.fk_parents`` / ``cfg.fk_offsets``: a joint's position is its parent's plus the
    parent's rotation applied to its rest offset, except the joints whose translation the pose sets
    (``cfg.fk_translated``: the root and its chain to the hips), which take ``position``. These are the
    positions of the motion :func:`jaxgest.zeggs.features.features_to_motion` renders. The rotations are
    already in the root frame (not parent-relative), so FK is one sum of rotated bones per joint.
    References: Ghorbani et al. 2023, §4.3 (losses "in both local and world spaces"); the authors' train.py
    (character/world terms by FK of the predicted rotations).
    """
    from jaxgest.zeggs.features import fk_chain_matrix

    j = cfg.num_joints
    if len(cfg.fk_parents) != j or len(cfg.fk_offsets) != 3 * j:
        raise ValueError(f"fk_parents / fk_offsets describe {len(cfg.fk_parents)} joints, the model has {j}")
    anchor, chain = fk_chain_matrix(cfg.fk_parents, cfg.fk_translated)
    parents = np.maximum(np.asarray(cfg.fk_parents), 0)
    offsets = jnp.asarray(np.asarray(cfg.fk_offsets, np.float32).reshape(j, 3), position.dtype)
    mats = rotations.sixd_to_matrix(rotation)  # (..., j, 3, 3), columns = rotated axes
    bones = jnp.einsum("...kab,kb->...ka", mats[..., parents, :, :], offsets)
    return position[..., anchor, :] + jnp.einsum("jk,...kc->...jc", jnp.asarray(chain, position.dtype), bones)


def reconstruction_terms(pred_pose: jax.Array, pred_root_position: jax.Array, pred_root_rotation: jax.Array,
                         target_pose: jax.Array, target_root_position: jax.Array,
                         target_root_rotation: jax.Array, *, cfg: ModelConfig,
                         frame_weight: jax.Array | None = None) -> dict[str, jax.Array]:
    """Every unweighted MAE term of eq. 2, each ``(batch,)``.

    Poses ``(batch, T, P)`` *denormalised*; root positions ``(batch, T, 3)``, rotations ``(batch, T, 4)``.
    With the rig in ``cfg`` (``fk_parents``), every position term (local/world position and their finite
    differences) uses FK of the rotations, :func:`forward_kinematics` -- the motion that is rendered -- and
    ``predicted_position`` keeps the predicted position channels (which the generator reads back) near the
    target's; without it, the position terms use the predicted channels and ``predicted_position`` is 0.
    Keys: local/world position (L_p), local/world rotation (L_r), local/world velocity (L_vp), local/world
    angular (L_vr), fd_local/world_position (L_dp), fd_local/world_rotation (L_dr), facing (L_f) and the
    root terms of the authors' code (root_position, root_rotation, root_velocity, root_angular).
    ``frame_weight`` ``(batch, T)`` (optional, not the paper): per-frame weights of every term (a finite
    difference weighs by the product of its two frames'), e.g. 0 on frames left out of the loss.
    References: Ghorbani et al. 2023, eq. 2.
    """
    chex.assert_equal_shape([pred_pose, target_pose])
    fps = cfg.fps
    p, t = split_pose(pred_pose, cfg), split_pose(target_pose, cfg)
    fd_weight = None if frame_weight is None else frame_weight[:, 1:] * frame_weight[:, :-1]

    def _mae(a, b):
        return mae(a, b, frame_weight)

    def mae_fd(a, b):  # MAE of the finite-difference velocities
        return mae(finite_difference(a, fps), finite_difference(b, fps), fd_weight)

    if cfg.fk_parents:  # positions of the rendered motion: FK of the rotations (both sides)
        raw = _mae(p["position"], t["position"])
        p = {**p, "position": forward_kinematics(p["rotation"], p["position"], cfg)}
        t = {**t, "position": forward_kinematics(t["rotation"], t["position"], cfg)}
    else:
        raw = jnp.zeros(pred_pose.shape[:1], pred_pose.dtype)
    pw = to_world(p, pred_root_position, pred_root_rotation)
    tw = to_world(t, target_root_position, target_root_rotation)
    return {
        "predicted_position": raw,
        "local_position": _mae(p["position"], t["position"]),
        "world_position": _mae(pw["position"], tw["position"]),
        "local_rotation": _mae(p["rotation"], t["rotation"]),
        "world_rotation": _mae(pw["rotation"], tw["rotation"]),
        "local_velocity": _mae(p["velocity"], t["velocity"]),
        "world_velocity": _mae(pw["velocity"], tw["velocity"]),
        "local_angular": _mae(p["angular"], t["angular"]),
        "world_angular": _mae(pw["angular"], tw["angular"]),
        "fd_local_position": mae_fd(p["position"], t["position"]),
        "fd_world_position": mae_fd(pw["position"], tw["position"]),
        "fd_local_rotation": mae_fd(p["rotation"], t["rotation"]),
        "fd_world_rotation": mae_fd(pw["rotation"], tw["rotation"]),
        "root_position": _mae(pred_root_position, target_root_position),
        "root_rotation": _mae(rotations.quat_to_matrix(pred_root_rotation),
                              rotations.quat_to_matrix(target_root_rotation)),
        "root_velocity": _mae(p["root_velocity"], t["root_velocity"]),
        "root_angular": _mae(p["root_angular"], t["root_angular"]),
        "facing": _mae(facing_direction(pred_root_rotation), facing_direction(target_root_rotation)),
    }


def term_weights(cfg: TrainConfig) -> dict[str, float]:
    """The weight of every reconstruction term (``cfg.w_<term>``)."""
    return {k: float(getattr(cfg, "w_" + k)) for k in (
        "local_position", "world_position", "local_rotation", "world_rotation", "local_velocity",
        "world_velocity", "local_angular", "world_angular", "fd_local_position", "fd_world_position",
        "fd_local_rotation", "fd_world_rotation", "root_position", "root_rotation", "root_velocity",
        "root_angular", "facing", "predicted_position")}


def kl_divergence(mu: jax.Array, logvar: jax.Array, *, reduction: str = "sum") -> jax.Array:
    """KL(N(mu, sigma^2) || N(0, I)) per example ``(batch,)``; >= 0 and 0 exactly at the prior.

    ``reduction="sum"`` over the D_e dimensions is the exact KL; ``"mean"`` divides it by D_e (the
    authors' code). References: Ghorbani et al. 2023, eq. 1; Kingma & Welling 2013, App. B.
    """
    per_dim = 0.5 * (jnp.exp(logvar) - 1.0 - logvar + jnp.square(mu))
    return jnp.sum(per_dim, -1) if reduction == "sum" else jnp.mean(per_dim, -1)


def kl_weight(step, *, center: float = 7500.0, growth: float = 0.005, cap: float = 0.2) -> jax.Array:
    """KL annealing weight: logistic ``1 / (1 + exp(-growth (step - center)))`` capped at ``cap``.

    Non-decreasing in ``step``; works on Python ints and traced steps.
    References: Bowman et al. 2016 (cost annealing), as used by Ghorbani et al. 2023, §4.3; schedule
    constants from the authors' code (centre 7.5k steps, growth 0.005, cap 0.2).
    """
    s = jnp.asarray(step, jnp.float32)
    return jnp.minimum(jax.nn.sigmoid(growth * (s - center)), cap)


def total_loss(terms: dict[str, jax.Array], kl: jax.Array, kl_w: jax.Array, *, cfg: TrainConfig) -> jax.Array:
    """Negative ELBO of eq. 1 per example: ``loss_scale * (sum_k w_k term_k + kl_w * KL)``, ``(batch,)``.

    References: Ghorbani et al. 2023, eqs. 1-2.
    """
    weights = term_weights(cfg)
    recon = sum(weights[k] * terms[k] for k in weights)
    return cfg.loss_scale * (recon + kl_w * kl)

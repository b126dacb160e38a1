"""The ZeroEGGS authors' training objective (paper 001 eqs. 1-2 as their ``train.py`` computes it), in JAX.

Per batch of windows, output ``O`` (the decoder's rollout, :data:`network.STATE_KEYS`) against target ``W``:

* the root velocities are taken to world space with the previous frame's root rotation (frame 0 its own);
* the root joint's local position / 2-axis rotation / velocities are put in world space through the root
  (``lpos_0 = q lpos_0 + r``; ``lvel_0 = v_r + q lvel_0 + w_r x (q lpos_0)``; ``lvrt_0 = w_r + q lvrt_0``);
* forward kinematics with velocities (their ``xform_fk_vel``) gives the character-space ("world")
  positions, rotation matrices, velocities and angular velocities;
* 17 mean absolute errors, each with its weight inside the mean, as theirs::

    root: pos 0.1, rot (matrix) 10, vel 0.1, vrt 5
    local: pos 15, rot (2-axis) 15, vel 10, vrt 7                     (lambda_p, lambda_r, lambda_vp, lambda_vr)
    character: pos 0.1, rot (matrix) 3, vel 0.06, vrt 1.25            (the paper's "world space")
    finite-difference velocities: local pos 7, local 2-axis 8, character pos 0.06, character matrix 1.25
    gaze direction in the root frame (unit): 10

* the KL term ``w(step) * mean_b mean_d KL`` with their logistic annealing (centre 7500, growth 0.005,
  capped at 0.2), and the total divided by 18.

Note that the root joint's local terms are taken *after* it is moved to world space (their order of
operations), so they weigh the root's world position by 15 as well.

References: Ghorbani et al. 2023, §4.3, eqs. 1-2; the authors' ``train.py`` (loss block) and
``modules.compute_KL_div``; Bowman et al. 2016 (KL annealing).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.zeggs.official import quat

#: (term, weight) in the order of their ``loss = (...)`` sum; every term is ``mean(|weight * error|)``.
WEIGHTS = {
    "root_pos": 0.1, "root_rot": 10.0, "root_vel": 0.1, "root_vrt": 5.0,
    "lpos": 15.0, "lrot": 15.0, "lvel": 10.0, "lvrt": 7.0,
    "cpos": 0.1, "crot": 3.0, "cvel": 0.06, "cvrt": 1.25,
    "ldvl": 7.0, "ldvt": 8.0, "cdvl": 0.06, "cdvt": 1.25,
    "gaze": 10.0,
}
DIVISOR = 18.0  # theirs: the 17 terms and the KL summed, divided by 18
KL_CENTER, KL_GROWTH, KL_CAP = 7500.0, 0.005, 0.2


def quat_to_matrix(q):
    """Their ``quat_to_xform``: ``(..., 4)`` -> ``(..., 3, 3)``."""
    w, x, y, z = (q[..., i:i + 1] for i in range(4))
    x2, y2, z2 = x + x, y + y, z + z
    xx, yy, wx, xy, yz, wy, xz, zz, wz = x * x2, y * y2, w * x2, x * y2, y * z2, w * y2, x * z2, z * z2, w * z2
    rows = [jnp.concatenate(r, axis=-1)[..., None, :] for r in (
        [1.0 - (yy + zz), xy - wz, xz + wy], [xy + wz, 1.0 - (xx + zz), yz - wx], [xz - wy, yz + wx, 1.0 - (xx + yy)])]
    return jnp.concatenate(rows, axis=-2)


def orthogonalize_from_xy(xy, eps: float = 1e-10):
    """Their ``xform_orthogonalize_from_xy``: 2-axis ``(..., 2, 3)`` -> rotation matrices ``(..., 3, 3)``."""
    xa = xy[..., 0:1, :]
    za = jnp.cross(xa, xy[..., 1:2, :])
    ya = jnp.cross(za, xa)
    rows = [a / (jnp.linalg.norm(a, axis=-1)[..., None] + eps) for a in (xa, ya, za)]
    return jnp.swapaxes(jnp.concatenate(rows, axis=-2), -1, -2)


def fk_vel(lmat, lpos, lvrt, lvel, parents):
    """Their ``xform_fk_vel``: character-space matrices, positions, angular and linear velocities."""
    gr, gp, gt, gv = [lmat[..., :1, :, :]], [lpos[..., :1, :]], [lvrt[..., :1, :]], [lvel[..., :1, :]]
    for i in range(1, len(parents)):
        p = parents[i]
        off = jnp.matmul(gr[p], lpos[..., i:i + 1, :][..., None])[..., 0]
        gp.append(gp[p] + off)
        gr.append(jnp.matmul(gr[p], lmat[..., i:i + 1, :, :]))
        gt.append(gt[p] + jnp.matmul(gr[p], lvrt[..., i:i + 1, :][..., None])[..., 0])
        gv.append(gv[p] + jnp.matmul(gr[p], lvel[..., i:i + 1, :][..., None])[..., 0] + jnp.cross(gt[p], off))
    return (jnp.concatenate(gr, axis=-3), jnp.concatenate(gp, axis=-2), jnp.concatenate(gt, axis=-2),
            jnp.concatenate(gv, axis=-2))


def _normalize(x, eps: float = 1e-8):
    return x / (jnp.linalg.norm(x, axis=-1, keepdims=True) + eps)


def _world(s: dict, parents) -> dict:
    """Root velocities in world space, the root joint through the root transform, then FK (theirs)."""
    q, r = s["root_rot"], s["root_pos"]
    vel = jnp.concatenate([quat.mul_vec(q[:, 0:1], s["root_vel"][:, 0:1], jnp),
                           quat.mul_vec(q[:, :-1], s["root_vel"][:, 1:], jnp)], axis=1)
    vrt = jnp.concatenate([quat.mul_vec(q[:, 0:1], s["root_vrt"][:, 0:1], jnp),
                           quat.mul_vec(q[:, :-1], s["root_vrt"][:, 1:], jnp)], axis=1)
    lmat = orthogonalize_from_xy(s["ltxy"])
    lpos0 = quat.mul_vec(q, s["lpos"][:, :, 0], jnp) + r
    lmat0 = jnp.matmul(quat_to_matrix(q), lmat[:, :, 0])
    lvel0 = vel + quat.mul_vec(q, s["lvel"][:, :, 0], jnp) + jnp.cross(vrt, quat.mul_vec(q, s["lpos"][:, :, 0], jnp))
    lvrt0 = vrt + quat.mul_vec(q, s["lvrt"][:, :, 0], jnp)
    lpos = jnp.concatenate([lpos0[:, :, None], s["lpos"][:, :, 1:]], axis=2)
    lmat = jnp.concatenate([lmat0[:, :, None], lmat[:, :, 1:]], axis=2)
    lvel = jnp.concatenate([lvel0[:, :, None], s["lvel"][:, :, 1:]], axis=2)
    lvrt = jnp.concatenate([lvrt0[:, :, None], s["lvrt"][:, :, 1:]], axis=2)
    cmat, cpos, cvrt, cvel = fk_vel(lmat, lpos, lvrt, lvel, parents)
    return dict(root_vel=vel, root_vrt=vrt, lpos=lpos, ltxy=s["ltxy"], lvel=lvel, lvrt=lvrt, cmat=cmat, cpos=cpos,
                cvrt=cvrt, cvel=cvel, root_mat=quat_to_matrix(q))


def reconstruction_terms(out: dict, target: dict, gaze_pos, parents, dt: float) -> dict:
    """The 17 weighted MAE terms of their ``train.py`` (each a scalar, weight included), ``out`` and
    ``target`` state dicts ``(B, T, ...)`` (:data:`network.STATE_KEYS`), ``gaze_pos (B, T, 3)``.
    References: the authors' ``train.py``; Ghorbani et al. 2023, eq. 2."""
    O, W = _world(out, parents), _world(target, parents)

    def mae(key_o, key_w, w):
        return jnp.mean(jnp.abs(w * (key_o - key_w)))

    def fd(a):
        return (a[:, 1:] - a[:, :-1]) / dt

    W_gaze = quat.mul_vec(quat.inv(target["root_rot"], jnp), _normalize(gaze_pos - target["root_pos"]), jnp)
    O_gaze = quat.mul_vec(quat.inv(out["root_rot"], jnp), _normalize(gaze_pos - out["root_pos"]), jnp)
    w = WEIGHTS
    return {
        "root_pos": mae(out["root_pos"], target["root_pos"], w["root_pos"]),
        "root_rot": mae(O["root_mat"], W["root_mat"], w["root_rot"]),
        "root_vel": mae(O["root_vel"], W["root_vel"], w["root_vel"]),
        "root_vrt": mae(O["root_vrt"], W["root_vrt"], w["root_vrt"]),
        "lpos": mae(O["lpos"], W["lpos"], w["lpos"]),
        "lrot": mae(out["ltxy"], target["ltxy"], w["lrot"]),
        "lvel": mae(O["lvel"], W["lvel"], w["lvel"]),
        "lvrt": mae(O["lvrt"], W["lvrt"], w["lvrt"]),
        "cpos": mae(O["cpos"], W["cpos"], w["cpos"]),
        "crot": mae(O["cmat"], W["cmat"], w["crot"]),
        "cvel": mae(O["cvel"], W["cvel"], w["cvel"]),
        "cvrt": mae(O["cvrt"], W["cvrt"], w["cvrt"]),
        "ldvl": mae(fd(O["lpos"]), fd(W["lpos"]), w["ldvl"]),
        "ldvt": mae(fd(out["ltxy"]), fd(target["ltxy"]), w["ldvt"]),
        "cdvl": mae(fd(O["cpos"]), fd(W["cpos"]), w["cdvl"]),
        "cdvt": mae(fd(O["cmat"]), fd(W["cmat"]), w["cdvt"]),
        "gaze": mae(O_gaze, W_gaze, w["gaze"]),
    }


def kl_weight(step):
    """Their KL annealing weight: ``min(1 / (1 + exp(-0.005 (step - 7500))), 0.2)`` (works traced)."""
    s = jnp.asarray(step, jnp.float32)
    return jnp.minimum(1.0 / (1.0 + jnp.exp(-KL_GROWTH * (s - KL_CENTER))), KL_CAP)


def kl_divergence(mu, logvar):
    """Their ``compute_KL_div``'s divergence: ``-0.5 mean_b mean_d (1 + logvar - mu^2 - exp(logvar))``.
    References: Kingma & Welling 2013, App. B; the authors' ``modules.compute_KL_div``."""
    return jnp.mean(-0.5 * jnp.mean(1.0 + logvar - jnp.square(mu) - jnp.exp(logvar), axis=1))


def total_loss(terms: dict, kl=None, step=0):
    """``(sum of the 17 terms + w(step) KL) / 18`` (eq. 1 as theirs); ``kl`` None for label-based models."""
    total = sum(terms[k] for k in WEIGHTS)
    if kl is not None:
        total = total + kl_weight(step) * kl
    return total / DIVISOR


def terms_numpy(terms: dict) -> dict:
    """The terms as Python floats (logging)."""
    return {k: float(np.asarray(v)) for k, v in jax.device_get(terms).items()}

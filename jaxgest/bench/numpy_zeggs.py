"""NumPy reference of the ZeroEGGS generator (benchmarks only): the same weights, an independent loop.

Written from the equations of :mod:`jaxgest.zeggs.generator` (hidden-state initializer: 3 linear layers,
ELU after the first two; per frame: input layer + ELU, two PyTorch-layout GRU layers, output layer, root
integration ``q_t = exp(q_{t-1} w_t dt) q_{t-1}``, ``p_t = p_{t-1} + q_t v_t dt``), not from its code: the
benchmark's equality check compares two implementations. Matrix products are float32 2-D GEMMs (OpenBLAS);
the root integration is float64 (it is 7 numbers per pose).

References: Ghorbani et al. 2023, §3.3 (Fig. 4); Cho et al. 2014 and PyTorch ``nn.GRU`` (gate layout
r, z, n with the hidden bias of n inside the reset product).
"""

from __future__ import annotations

import numpy as np


def _f32(tree):
    if isinstance(tree, dict) or hasattr(tree, "items"):
        return {k: _f32(v) for k, v in tree.items()}
    return np.asarray(tree, np.float32)


def _dense(p, x):
    return x @ p["kernel"] + p["bias"]


def _elu(x):
    return np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))


def _sigmoid(x):
    return 0.5 * (np.tanh(0.5 * x) + 1.0)


def _qmul(a, b):
    aw, ax, ay, az = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    bw, bx, by, bz = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], axis=1)


def _qrot(q, v):
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _qinv(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _expmap_to_quat(v):
    angle = np.linalg.norm(v, axis=1, keepdims=True)
    safe = np.maximum(angle, 1e-12)
    half_sinc = np.where(angle < 1e-4, 0.5 - angle ** 2 / 48.0, np.sin(0.5 * angle) / safe)
    return np.concatenate([np.cos(0.5 * angle), v * half_sinc], axis=1)


def _gru(p, h, x):
    H = h.shape[1]
    gi, gh = _dense(p["input"], x), _dense(p["hidden"], h)
    r = _sigmoid(gi[:, :H] + gh[:, :H])
    z = _sigmoid(gi[:, H:2 * H] + gh[:, H:2 * H])
    n = np.tanh(gi[:, 2 * H:] + r * gh[:, 2 * H:])
    return (1.0 - z) * n + z * h


def generate(params, speech, style, pose0, root_position0, root_rotation0, facing, *, fps: float,
             root_velocity: slice, root_angular_velocity: slice):
    """The generator with identity pose normalisation; same inputs and output dict as the JAX one.

    params: the ``generator`` subtree (``initializer``, ``decoder``), any array type. speech ``(b, T, D_S)``
    embeddings, style ``(b, D_e)``, pose0 ``(b, P)``, root_position0 / facing ``(b, 3)``, root_rotation0
    ``(b, 4)``. Returns ``{"pose": (b, T, P), "root_position": (b, T, 3), "root_rotation": (b, T, 4)}``.
    """
    P = _f32(params)
    dec, ini = P["decoder"], P["initializer"]
    speech, style = np.asarray(speech, np.float32), np.asarray(style, np.float32)
    y = np.asarray(pose0, np.float32)
    pos = np.asarray(root_position0, np.float64)
    rot = np.asarray(root_rotation0, np.float64)
    facing = np.asarray(facing, np.float64)
    dt = 1.0 / fps

    def local_facing(q):
        return _qrot(_qinv(q), facing).astype(np.float32)

    x = np.concatenate([y, local_facing(rot), style], axis=1)
    x = _elu(_dense(ini["layer0"], x))
    x = _elu(_dense(ini["layer1"], x))
    hidden = np.split(_dense(ini["layer2"], x), 2, axis=1)
    ys, ps, qs = [y], [pos], [rot]
    for t in range(1, speech.shape[1]):
        x = np.concatenate([y, local_facing(rot), speech[:, t], style], axis=1)
        h = np.concatenate([_elu(_dense(dec["input_layer"], x)), x], axis=1)
        for i in range(len(hidden)):
            h = hidden[i] = _gru(dec[f"gru{i}"], hidden[i], h)
        y = _dense(dec["output_layer"], h)
        vel = y[:, root_velocity].astype(np.float64)
        ang = y[:, root_angular_velocity].astype(np.float64)
        rot = _qmul(_expmap_to_quat(_qrot(rot, ang) * dt), rot)
        rot = rot / np.linalg.norm(rot, axis=1, keepdims=True)
        pos = pos + _qrot(rot, vel) * dt
        ys.append(y)
        ps.append(pos)
        qs.append(rot)
    return {"pose": np.stack(ys, 1), "root_position": np.stack(ps, 1), "root_rotation": np.stack(qs, 1)}

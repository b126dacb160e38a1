"""ZeroEGGS (:class:`ZeggsPeer`): the official generator (``ZEGGS/modules.py``): ``CellStateEncoder``
(3 Linear, ELU) for the initial hidden state, then per frame ``RecurrentDecoderNormal`` -- ``layer0``
Linear + ELU on ``[pose, speech, style]``, a 2-layer ``nn.GRU`` (``batch_first``, one time step per call,
as ``Decoder.forward`` loops over frames) on ``[hidden, pose, speech, style]``, ``layer2`` Linear -- and the
root integration in torch. The pose input is jaxgest's (``[pose * input scale, facing in the root frame]``)
so the same weights apply; the official code builds it with ``vectorize_input`` from its own features.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from jaxgest.bench.torch_peers.common import tensor


# --------------------------------------------------------------------------------------------------------
# ZeroEGGS: the official generator
# --------------------------------------------------------------------------------------------------------
class RecurrentDecoderNormal(nn.Module):
    """``ZEGGS/modules.py`` RecurrentDecoderNormal (one frame per call)."""

    def __init__(self, pose_input_size, speech_size, style_size, output_size, hidden_size, num_rnn_layers):
        super().__init__()
        all_input_size = pose_input_size + speech_size + style_size
        self.layer0 = nn.Linear(all_input_size, hidden_size)
        self.layer1 = nn.GRU(all_input_size + hidden_size, hidden_size, num_rnn_layers, batch_first=True)
        self.layer2 = nn.Linear(hidden_size, output_size)

    def forward(self, pose, speech, style, cell_state):
        hidden = F.elu(self.layer0(torch.cat([pose, speech, style], dim=-1)))
        cell_output, cell_state = self.layer1(torch.cat([hidden, pose, speech, style], dim=-1).unsqueeze(1),
                                              cell_state)
        output = self.layer2(cell_output.squeeze(1))
        return output, cell_state


class CellStateEncoder(nn.Module):
    """``ZEGGS/modules.py`` CellStateEncoder."""

    def __init__(self, input_size, hidden_size, num_rnn_layers):
        super().__init__()
        self.num_rnn_layers = num_rnn_layers
        self.layer0 = nn.Linear(input_size, hidden_size)
        self.layer1 = nn.Linear(hidden_size, hidden_size)
        self.layer2 = nn.Linear(hidden_size, hidden_size * num_rnn_layers)

    def forward(self, pose, style):
        hidden = F.elu(self.layer0(torch.cat([pose, style], dim=-1)))
        hidden = F.elu(self.layer1(hidden))
        output = self.layer2(hidden)
        return output.reshape(output.shape[0], self.num_rnn_layers, -1).swapaxes(0, 1).contiguous()


def quat_mul(a, b):
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], dim=-1)


def quat_rotate(q, v):
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * torch.cross(u, v, dim=-1)
    return v + w * t + torch.cross(u, t, dim=-1)


def quat_inv(q):
    return torch.cat([q[..., :1], -q[..., 1:]], dim=-1)


def expmap_to_quat(v):
    t2 = torch.sum(v * v, dim=-1, keepdim=True)
    small = t2 < 1e-8
    t = torch.sqrt(torch.where(small, torch.ones_like(t2), t2))
    half_sinc = torch.where(small, 0.5 - t2 / 48.0, torch.sin(0.5 * t) / t)
    w = torch.where(small, 1.0 - t2 / 8.0, torch.cos(0.5 * t))
    return torch.cat([w, v * half_sinc], dim=-1)


class ZeggsPeer(nn.Module):
    """The official generator loop: initial hidden state, then per frame decoder + root integration."""

    def __init__(self, cfg):
        super().__init__()
        self.cfg = cfg
        pin = cfg.pose_dim + cfg.facing_dim
        H = cfg.gru_hidden
        if cfg.init_hidden != H:
            raise ValueError("the official CellStateEncoder has hidden size = GRU size")
        self.cell_state_encoder = CellStateEncoder(pin + cfg.style_embedding, H, cfg.gru_layers)
        self.recurrent_decoder = RecurrentDecoderNormal(pin, cfg.speech_embedding, cfg.style_embedding,
                                                        cfg.pose_dim, H, cfg.gru_layers)
        lay = cfg.layout
        self.vel = torch.as_tensor(np.arange(cfg.pose_dim)[lay.root_velocity])
        self.ang = torch.as_tensor(np.arange(cfg.pose_dim)[lay.root_angular_velocity])

    def frame(self, pose, pos, rot, state, speech, style, facing, in_scale, vel_m, vel_s, ang_m, ang_s):
        """One generated frame (the body of ``Decoder.forward``'s loop): -> (pose, pos, rot, state)."""
        dt = 1.0 / self.cfg.fps
        x = torch.cat([pose * in_scale, quat_rotate(quat_inv(rot), facing)], dim=-1)
        pose, state = self.recurrent_decoder(x, speech, style, state)
        vel = pose[:, self.vel] * vel_s + vel_m
        ang = pose[:, self.ang] * ang_s + ang_m
        rot = quat_mul(expmap_to_quat(quat_rotate(rot, ang) * dt), rot)
        rot = rot / torch.clamp(torch.linalg.norm(rot, dim=-1, keepdim=True), min=1e-12)
        pos = pos + quat_rotate(rot, vel) * dt
        return pose, pos, rot, state

    def forward(self, speech, style, pose0, root_position0, root_rotation0, facing, mean, std, in_scale,
                frame=None):
        """The whole clip; ``frame``: the per-frame function (default :meth:`frame`; a compiled
        one for the compiled peer: compiling the per-frame step, not a 300-times unrolled loop)."""
        frame = frame or self.frame
        pose, pos, rot = pose0, root_position0, root_rotation0
        state = self.cell_state_encoder(torch.cat([pose * in_scale, quat_rotate(quat_inv(rot), facing)], -1),
                                        style)
        poses, positions, rotations = [pose], [pos], [rot]
        vel_m, vel_s = mean[self.vel], std[self.vel]
        ang_m, ang_s = mean[self.ang], std[self.ang]
        for i in range(1, speech.shape[1]):
            pose, pos, rot, state = frame(pose, pos, rot, state, speech[:, i], style, facing, in_scale,
                                          vel_m, vel_s, ang_m, ang_s)
            poses.append(pose)
            positions.append(pos)
            rotations.append(rot)
        return torch.stack(poses, 1), torch.stack(positions, 1), torch.stack(rotations, 1)


def load_zeggs(cfg, params) -> ZeggsPeer:
    """A :class:`ZeggsPeer` holding the JAX generator parameters (``params["generator"]``)."""
    peer = ZeggsPeer(cfg).eval()
    g = params["generator"]
    ini, dec = g["initializer"], g["decoder"]

    def lin(mod, p):
        mod.weight.copy_(tensor(np.asarray(p["kernel"]).T))
        mod.bias.copy_(tensor(p["bias"]))

    with torch.no_grad():
        for i in range(3):
            lin(getattr(peer.cell_state_encoder, f"layer{i}"), ini[f"layer{i}"])
        rd = peer.recurrent_decoder
        lin(rd.layer0, dec["input_layer"])
        lin(rd.layer2, dec["output_layer"])
        for i in range(cfg.gru_layers):
            gp = dec[f"gru{i}"]
            getattr(rd.layer1, f"weight_ih_l{i}").copy_(tensor(np.asarray(gp["input"]["kernel"]).T))
            getattr(rd.layer1, f"bias_ih_l{i}").copy_(tensor(gp["input"]["bias"]))
            getattr(rd.layer1, f"weight_hh_l{i}").copy_(tensor(np.asarray(gp["hidden"]["kernel"]).T))
            getattr(rd.layer1, f"bias_hh_l{i}").copy_(tensor(gp["hidden"]["bias"]))
    return peer


def zeggs_call(peer: ZeggsPeer, in_scale: np.ndarray, frame=None):
    """``f(params, speech, style, pose0, root_position0, root_rotation0, facing) -> dict`` (NumPy out).

    Identity normalisation (mean 0, std 1), as the benchmark's JAX generator call. ``frame``: the per-frame
    function (:meth:`ZeggsPeer.frame` or a compiled one)."""
    P = peer.cfg.pose_dim
    mean, std = torch.zeros(P), torch.ones(P)
    scale = tensor(in_scale)

    def run(_params, speech, style, pose0, root_position0, root_rotation0, facing):
        args = [torch.from_numpy(np.array(a, np.float32)) for a in
                (speech, style, pose0, root_position0, root_rotation0, facing)]
        with torch.inference_mode():
            y, p, q = peer(*args, mean, std, scale, frame=frame)
        return {"pose": y.numpy(), "root_position": p.numpy(), "root_rotation": q.numpy()}

    return run

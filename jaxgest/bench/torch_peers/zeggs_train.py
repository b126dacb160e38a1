"""Training-step peer of ZeroEGGS in PyTorch: one RAdam step on the negative ELBO (eqs. 1-2).

:class:`ZeggsStepPeer` holds the JAX parameters (``init_params`` layout) in PyTorch modules and runs one
whole step of :func:`jaxgest.zeggs.steps.make_train_step` per call: speech encoder, style encoder (VAE
posterior), reparameterised style sample, the official generator loop
(:class:`jaxgest.bench.torch_peers.zeggs.ZeggsPeer`, the authors' module structure: ``CellStateEncoder``,
``RecurrentDecoderNormal`` with a 2-layer ``nn.GRU`` stepped once per frame, root integration), every
reconstruction term of eq. 2 (with FK position terms when the config carries a rig), the KL term with its
annealing weight, the total loss (eq. 1), ``backward()`` and ``torch.optim.RAdam``.

Ported: :mod:`jaxgest.zeggs.speech_encoder` (replicate-padded convs, ELU, framewise linear + ELU),
:mod:`jaxgest.zeggs.style_encoder` (convs + ReLU + LayerNorm with flax's epsilon 1e-6, sinusoidal positions,
the FFT block's masked multi-head attention with flax ``MultiHeadDotProductAttention``'s parameter layout --
query/key/value ``(in, heads, head_dim)``, out ``(heads, head_dim, out)``, query scaled by ``head_dim**-0.5``,
masked logits set to the float32 minimum -- the conv feed-forward, masked mean, optional projection),
:func:`~jaxgest.zeggs.style_encoder.sample_style`, :mod:`jaxgest.zeggs.losses` (``reconstruction_terms``
including ``forward_kinematics``, ``kl_divergence`` both reductions, ``kl_weight``, ``total_loss``) and the
initial-pose shuffle of :func:`jaxgest.zeggs.steps.initial_poses` (``initial_pose_shuffle`` /
``initial_pose_source``, rows to swap given).

Not ported, refused with a ``ValueError`` naming the field: dropout (``speech_dropout``, ``style_dropout``,
``style_attention_dropout`` must be 0: JAX's dropout masks cannot be reproduced in torch, so the comparison
runs without dropout), ``initial_pose_mask_seconds`` with a shuffle (per-frame loss weights),
``init_hidden != gru_hidden`` (the official ``CellStateEncoder``). Speed augmentation and mirroring are
in the data pipeline, not in the step.

Randomness: the JAX step draws the style sample ``eps`` (and the rows whose initial pose is swapped) from
keys derived from the step key; the peer takes them as given (``draws``), computed from the same key
derivation (:func:`jaxgest.bench.cases.peers_train.step_draws`), and keeps them for every call (the JAX step
of the benchmark is also called on the same state and key each time). The KL weight follows the peer's own
step count (as the JAX step's follows ``state.step``); the learning rate is the schedule's at step 0
(constant: the staircase decay changes it only after ``lr_decay_steps``).

Optimiser: ``torch.optim.RAdam`` (betas 0.9 / 0.999, eps 1e-8, no weight decay) against ``optax.radam``.
Both take the un-rectified step ``lr * m_hat`` while the SMA length rho_t is at most 5 (the first 5 steps;
rho_1 = 1, so the first update is exactly ``lr * g``): on those steps they agree to float32 rounding
(measured: <= 1.3e-6 relative). From step 6 they differ by ~1 % (1.2 % at step 6, 0.3 % at step 12,
shrinking): optax computes rho_t = rho_inf - 2 t b2^t / (1 - b2^t) in float32, a cancellation of ~2000 -
~1994 (rho_6 = 5.955 instead of 5.994), torch in float64, and the rectification factor amplifies it.
Only the first step is compared, where both are exact; the cost of a step does not depend on it.

``compiled=True``: ``torch.compile`` (static shapes) of the speech encoder, the style encoder, the per-frame
generator step (:meth:`ZeggsPeer.frame`, as :mod:`jaxgest.bench.torch_peers.compiled` compiles it for
inference: compiling the whole loop would unroll it once per frame), the losses (reconstruction, KL,
total), each forward and, through AOTAutograd, backward, and the optimiser step. The frame loop and the
3-layer hidden-state initialiser stay eager.

Observables per call (as :func:`jaxgest.bench.cases.peers_train.step_observables`): the loss, ``recon``,
``kl``, ``kl_weight`` (at step 0 the KL is ~1e-5 of the loss on a random batch, so the loss alone would not
catch a wrong KL weight) and every reconstruction term (batch means, before the update), ``grad_norm``
(``||m_1|| / (1 - beta1)`` from RAdam's first moment) and ``update_norm``.

References: Ghorbani et al. 2023, §3 (Fig. 2-4), §4.2-4.3, eqs. 1-2; Liu et al. 2019 (RAdam).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from jaxgest.bench.torch_peers.common import tensor
from jaxgest.bench.torch_peers.tgst_train import _StepPeer
from jaxgest.bench.torch_peers.zeggs import load_zeggs, quat_rotate

LN_EPS = 1e-6  # flax.linen.LayerNorm's default epsilon (torch's is 1e-5)
TERMS = ("local_position", "world_position", "local_rotation", "world_rotation", "local_velocity",
         "world_velocity", "local_angular", "world_angular", "fd_local_position", "fd_world_position",
         "fd_local_rotation", "fd_world_rotation", "root_position", "root_rotation", "root_velocity",
         "root_angular", "facing", "predicted_position")  # losses.term_weights' order


def _pad_time(x, kernel: int, mode: str):
    """Pad ``(B, C, T)`` along T as flax "SAME" (zeros) or replicate (:func:`speech_encoder.replicate_pad`)."""
    left = (kernel - 1) // 2
    return F.pad(x, (left, kernel - 1 - left), mode=mode)


class SpeechEncoder(nn.Module):
    """:class:`jaxgest.zeggs.speech_encoder.SpeechEncoder` (dropout 0)."""

    def __init__(self, cfg):
        super().__init__()
        chans = (cfg.speech_dim,) + tuple(cfg.speech_channels)
        self.kernels = tuple(cfg.speech_kernels)
        self.convs = nn.ModuleList(nn.Conv1d(a, b, k) for a, b, k in zip(chans, chans[1:], self.kernels))
        self.linear = nn.Linear(chans[-1], cfg.speech_embedding)

    def forward(self, speech):
        x = speech.transpose(1, 2)
        for conv, k in zip(self.convs, self.kernels):
            x = F.elu(conv(_pad_time(x, k, "replicate")))
        return F.elu(self.linear(x.transpose(1, 2)))


class FFTBlock(nn.Module):
    """:class:`jaxgest.zeggs.style_encoder.FFTBlock`: masked MHA + res + LN, conv FF + res + LN."""

    def __init__(self, d: int, heads: int, kernel: int):
        super().__init__()
        self.heads, self.kernel = heads, kernel
        self.query, self.key, self.value, self.out = (nn.Linear(d, d) for _ in range(4))
        self.attention_norm = nn.LayerNorm(d, eps=LN_EPS)
        self.ff_conv0, self.ff_conv1 = nn.Conv1d(d, d, kernel), nn.Conv1d(d, d, kernel)
        self.ff_norm = nn.LayerNorm(d, eps=LN_EPS)

    def conv(self, conv, x):  # (B, S, d) -> (B, S, d), "SAME"
        return conv(_pad_time(x.transpose(1, 2), self.kernel, "constant")).transpose(1, 2)

    def forward(self, x, mask):
        b, s, d = x.shape
        h, hd = self.heads, d // self.heads
        m = mask[..., None].to(x.dtype)
        q, k, v = (lin(x).reshape(b, s, h, hd) for lin in (self.query, self.key, self.value))
        logits = torch.einsum("bqhd,bkhd->bhqk", q / math.sqrt(hd), k)
        both = mask[:, None, :, None] & mask[:, None, None, :]  # nn.make_attention_mask(mask, mask)
        logits = torch.where(both, logits, torch.finfo(logits.dtype).min)
        attn = torch.einsum("bhqk,bkhd->bqhd", torch.softmax(logits, -1), v).reshape(b, s, d)
        y = self.attention_norm(self.out(attn) + x) * m
        f = F.relu(self.conv(self.ff_conv0, y)) * m
        f = self.conv(self.ff_conv1, f)
        return self.ff_norm(f + y) * m


class StyleEncoder(nn.Module):
    """:class:`jaxgest.zeggs.style_encoder.StyleEncoder` (dropout 0): -> ``(mu, logvar)``."""

    def __init__(self, cfg):
        super().__init__()
        d = cfg.style_model_dim
        self.kernel, self.embedding = cfg.style_kernel, cfg.style_embedding
        self.conv0 = nn.Conv1d(cfg.pose_dim, cfg.style_hidden, cfg.style_kernel)
        self.conv0_norm = nn.LayerNorm(cfg.style_hidden, eps=LN_EPS)
        self.conv1 = nn.Conv1d(cfg.style_hidden, d, cfg.style_kernel)
        self.conv1_norm = nn.LayerNorm(d, eps=LN_EPS)
        self.fft = FFTBlock(d, cfg.style_heads, cfg.style_kernel)
        self.projection = nn.Linear(d, d) if cfg.style_projection else None

    def forward(self, style, mask, positions):
        m = mask[..., None].to(style.dtype)
        x = style * m
        for conv, norm in ((self.conv0, self.conv0_norm), (self.conv1, self.conv1_norm)):
            x = conv(_pad_time(x.transpose(1, 2), self.kernel, "constant")).transpose(1, 2)
            x = norm(F.relu(x)) * m
        x = (x + positions[None]) * m
        x = self.fft(x, mask)
        if self.projection is not None:
            x = self.projection(x)
        pooled = torch.sum(x * m, 1) / torch.clamp(torch.sum(m, 1), min=1.0)  # style_encoder.masked_mean
        return pooled[:, :self.embedding], pooled[:, self.embedding:]


# ------------------------------------------------------------------------------------------------------
# losses (jaxgest.zeggs.losses)
# ------------------------------------------------------------------------------------------------------
def quat_to_matrix(q):
    q = q / torch.clamp(torch.linalg.vector_norm(q, dim=-1, keepdim=True), min=1e-12)
    w, x, y, z = q.unbind(-1)
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x, y * y, z * z, x * y, x * z, y * z, w * x, w * y, w * z
    rows = [torch.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)], -1),
            torch.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)], -1),
            torch.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)], -1)]
    return torch.stack(rows, -2)


def sixd_to_matrix(d6):
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / torch.clamp(torch.linalg.vector_norm(a1, dim=-1, keepdim=True), min=1e-12)
    a2p = a2 - torch.sum(b1 * a2, -1, keepdim=True) * b1
    b2 = a2p / torch.clamp(torch.linalg.vector_norm(a2p, dim=-1, keepdim=True), min=1e-12)
    return torch.stack([b1, b2, torch.cross(b1, b2, dim=-1)], -1)


class Losses(nn.Module):
    """Eqs. 1-2 per example: every reconstruction term, KL, and the total (``losses.total_loss``)."""

    def __init__(self, model_cfg, train_cfg):
        super().__init__()
        from jaxgest.zeggs.features import fk_chain_matrix

        self.cfg, self.t = model_cfg, train_cfg
        lay, j = model_cfg.layout, model_cfg.num_joints
        idx = np.arange(model_cfg.pose_dim)
        self.slices = {k: torch.as_tensor(idx[getattr(lay, k)]) for k in (
            "local_positions", "local_rotations", "local_velocities", "local_angular_velocities",
            "root_velocity", "root_angular_velocity")}
        self.fk = bool(model_cfg.fk_parents)
        if self.fk:
            if len(model_cfg.fk_parents) != j or len(model_cfg.fk_offsets) != 3 * j:
                raise ValueError(f"fk_parents / fk_offsets describe {len(model_cfg.fk_parents)} joints, the "
                                 f"model has {j}")
            anchor, chain = fk_chain_matrix(model_cfg.fk_parents, model_cfg.fk_translated)
            self.anchor = torch.as_tensor(anchor)
            self.parents = torch.as_tensor(np.maximum(np.asarray(model_cfg.fk_parents), 0))
            self.chain = tensor(chain)
            self.offsets = tensor(np.asarray(model_cfg.fk_offsets, np.float32).reshape(j, 3))
        from jaxgest.zeggs.losses import term_weights

        self.weights = term_weights(train_cfg)

    def split(self, pose):
        lead, s = pose.shape[:-1], self.slices
        return {"position": pose[..., s["local_positions"]].reshape(lead + (-1, 3)),
                "rotation": pose[..., s["local_rotations"]].reshape(lead + (-1, 6)),
                "velocity": pose[..., s["local_velocities"]].reshape(lead + (-1, 3)),
                "angular": pose[..., s["local_angular_velocities"]].reshape(lead + (-1, 3)),
                "root_velocity": pose[..., s["root_velocity"]], "root_angular": pose[..., s["root_angular_velocity"]]}

    def forward_kinematics(self, rotation, position):
        mats = sixd_to_matrix(rotation)
        bones = torch.einsum("...kab,kb->...ka", mats[..., self.parents, :, :], self.offsets)
        return position[..., self.anchor, :] + torch.einsum("jk,...kc->...jc", self.chain, bones)

    @staticmethod
    def to_world(p, root_position, root_rotation):
        rot = p["rotation"]
        vecs = torch.stack([p["position"], rot[..., :3], rot[..., 3:], p["velocity"], p["angular"]], -2)
        w = torch.einsum("btij,btkvj->btkvi", quat_to_matrix(root_rotation), vecs)
        return {"position": w[..., 0, :] + root_position[..., None, :],
                "rotation": torch.cat([w[..., 1, :], w[..., 2, :]], -1), "velocity": w[..., 3, :],
                "angular": w[..., 4, :]}

    def reconstruction_terms(self, pred_pose, pred_rp, pred_rq, target_pose, target_rp, target_rq):
        fps = self.cfg.fps

        def mae(a, b):
            return torch.mean(torch.abs(a - b).reshape(a.shape[0], -1), 1)

        def mae_fd(a, b):
            return mae((a[:, 1:] - a[:, :-1]) * fps, (b[:, 1:] - b[:, :-1]) * fps)

        def facing(q):  # losses.facing_direction: the root's forward axis (world +Z)
            return quat_rotate(q, torch.tensor([0.0, 0.0, 1.0]).expand(q.shape[:-1] + (3,)))

        p, t = self.split(pred_pose), self.split(target_pose)
        if self.fk:
            raw = mae(p["position"], t["position"])
            p = {**p, "position": self.forward_kinematics(p["rotation"], p["position"])}
            t = {**t, "position": self.forward_kinematics(t["rotation"], t["position"])}
        else:
            raw = torch.zeros(pred_pose.shape[:1])
        pw, tw = self.to_world(p, pred_rp, pred_rq), self.to_world(t, target_rp, target_rq)
        return {
            "predicted_position": raw,
            "local_position": mae(p["position"], t["position"]),
            "world_position": mae(pw["position"], tw["position"]),
            "local_rotation": mae(p["rotation"], t["rotation"]),
            "world_rotation": mae(pw["rotation"], tw["rotation"]),
            "local_velocity": mae(p["velocity"], t["velocity"]),
            "world_velocity": mae(pw["velocity"], tw["velocity"]),
            "local_angular": mae(p["angular"], t["angular"]),
            "world_angular": mae(pw["angular"], tw["angular"]),
            "fd_local_position": mae_fd(p["position"], t["position"]),
            "fd_world_position": mae_fd(pw["position"], tw["position"]),
            "fd_local_rotation": mae_fd(p["rotation"], t["rotation"]),
            "fd_world_rotation": mae_fd(pw["rotation"], tw["rotation"]),
            "root_position": mae(pred_rp, target_rp),
            "root_rotation": mae(quat_to_matrix(pred_rq), quat_to_matrix(target_rq)),
            "root_velocity": mae(p["root_velocity"], t["root_velocity"]),
            "root_angular": mae(p["root_angular"], t["root_angular"]),
            "facing": mae(facing(pred_rq), facing(target_rq)),
        }

    def forward(self, pred_pose, pred_rp, pred_rq, target_pose, target_rp, target_rq, mu, logvar, kl_w,
                mean, std):
        """Batch means of ``loss`` (eq. 1), ``recon``, ``kl`` and every term; poses normalised."""
        terms = self.reconstruction_terms(pred_pose * std + mean, pred_rp, pred_rq, target_pose * std + mean,
                                          target_rp, target_rq)
        per_dim = 0.5 * (torch.exp(logvar) - 1.0 - logvar + mu * mu)  # losses.kl_divergence
        kl = torch.sum(per_dim, -1) if self.t.kl_reduction == "sum" else torch.mean(per_dim, -1)
        recon = sum(self.weights[k] * terms[k] for k in TERMS)
        out = {k: torch.mean(v) for k, v in terms.items()}
        out.update(loss=torch.mean(self.t.loss_scale * (recon + kl_w * kl)),
                   recon=torch.mean(self.t.loss_scale * recon), kl=torch.mean(kl), kl_weight=kl_w)
        return out


def kl_weight(step: int, train_cfg) -> float:
    """:func:`jaxgest.zeggs.losses.kl_weight` (float32 logistic, capped)."""
    s = torch.tensor(float(step), dtype=torch.float32)
    w = torch.sigmoid(train_cfg.kl_growth * (s - train_cfg.kl_center))
    return float(torch.clamp(w, max=train_cfg.kl_cap))


def check_config(cfg) -> None:
    """``ValueError`` naming the first field of ``cfg`` (a zeggs ``Config``) the peer does not port."""
    m, t = cfg.model, cfg.train
    for part, obj, field in (("model", m, "speech_dropout"), ("model", m, "style_dropout"),
                             ("model", m, "style_attention_dropout")):
        if getattr(obj, field):
            raise ValueError(f"the ZeroEGGS step peer runs without dropout: {part}.{field} must be 0, "
                             f"got {getattr(obj, field)}")
    if t.initial_pose_shuffle > 0 and round(t.initial_pose_mask_seconds * m.fps) > 0:
        raise ValueError("the ZeroEGGS step peer does not port train.initial_pose_mask_seconds (per-frame loss "
                         "weights): set it to 0")
    if m.init_hidden != m.gru_hidden:
        raise ValueError("the official CellStateEncoder has model.init_hidden = model.gru_hidden")


def _conv(mod, p):  # flax Conv kernel (k, in, out) -> torch Conv1d (out, in, k)
    mod.weight.copy_(tensor(np.transpose(np.asarray(p["kernel"]), (2, 1, 0))))
    mod.bias.copy_(tensor(p["bias"]))


def _mha_in(mod, p):  # DenseGeneral (in, heads, head_dim) -> Linear (heads * head_dim, in)
    k = np.asarray(p["kernel"])
    mod.weight.copy_(tensor(k.reshape(k.shape[0], -1).T))
    mod.bias.copy_(tensor(np.asarray(p["bias"]).reshape(-1)))


def _mha_out(mod, p):  # DenseGeneral (heads, head_dim, out) -> Linear (out, heads * head_dim)
    k = np.asarray(p["kernel"])
    mod.weight.copy_(tensor(k.reshape(-1, k.shape[-1]).T))
    mod.bias.copy_(tensor(p["bias"]))


def _norm(mod, p):
    mod.weight.copy_(tensor(p["scale"]))
    mod.bias.copy_(tensor(p["bias"]))


def load_encoders(cfg, params) -> tuple[SpeechEncoder, StyleEncoder]:
    """The two encoders holding ``params["speech_encoder"]`` / ``params["style_encoder"]`` (JAX layout)."""
    speech, style = SpeechEncoder(cfg), StyleEncoder(cfg)
    sp, st = params["speech_encoder"], params["style_encoder"]
    with torch.no_grad():
        for i, conv in enumerate(speech.convs):
            _conv(conv, sp[f"conv{i}"])
        _mha_in(speech.linear, sp["linear"])
        for i in range(2):
            _conv(getattr(style, f"conv{i}"), st[f"conv{i}"])
            _norm(getattr(style, f"conv{i}_norm"), st[f"conv{i}_norm"])
        f = st["fft"]
        for name in ("query", "key", "value"):
            _mha_in(getattr(style.fft, name), f["attention"][name])
        _mha_out(style.fft.out, f["attention"]["out"])
        _norm(style.fft.attention_norm, f["attention_norm"])
        _norm(style.fft.ff_norm, f["ff_norm"])
        _conv(style.fft.ff_conv0, f["ff_conv0"])
        _conv(style.fft.ff_conv1, f["ff_conv1"])
        if style.projection is not None:
            _mha_in(style.projection, st["projection"])
    return speech, style


class ZeggsStepPeer(_StepPeer):
    """RAdam step of the whole ZeroEGGS network; ``step(batch) -> observables`` (see the module docstring).

    ``cfg``: a :class:`jaxgest.zeggs.config.Config` (refused when :func:`check_config` says so);
    ``params``: ``init_params`` layout; ``stats``: ``{"mean", "std"}`` ``(P,)``; ``draws``: ``{"eps" (B, D_e),
    "swap" (B,) bool}`` the JAX step's style-sample noise and swapped initial-pose rows.
    """

    compile_whole_loss = False

    def __init__(self, cfg, params, stats, draws, *, compiled: bool = False, lr: float | None = None):
        from jaxgest.nn import sinusoidal_positions
        from jaxgest.zeggs.generator import input_scale

        check_config(cfg)
        self.cfg, m = cfg, cfg.model
        self.speech_encoder, self.style_encoder = load_encoders(m, params)
        self.generator = load_zeggs(m, params).train()
        self.losses = Losses(m, cfg.train)
        mean, std = np.asarray(stats["mean"], np.float32), np.asarray(stats["std"], np.float32)
        self.mean, self.std = tensor(mean), tensor(std)
        self.in_scale = tensor(np.asarray(input_scale(m, mean, std)))
        self.eps, self.swap = tensor(draws["eps"]), torch.from_numpy(np.array(draws["swap"], bool))
        self.sinusoid = sinusoidal_positions
        self.kl_w = torch.zeros(())
        self.steps_done = 0
        ps = [p for mod in (self.speech_encoder, self.style_encoder, self.generator) for p in mod.parameters()]
        super().__init__(ps, cfg.train.learning_rate if lr is None else lr, compiled, optimizer="radam")
        wrap = (lambda f: torch.compile(f, dynamic=False)) if compiled else (lambda f: f)
        self._speech, self._style = wrap(self.speech_encoder), wrap(self.style_encoder)
        self._frame, self._losses = wrap(self.generator.frame), wrap(self.losses)

    def inputs(self, batch):
        b = {k: torch.from_numpy(np.array(v)) for k, v in batch.items()}
        for k in ("speech", "pose", "root_position", "root_rotation", "style", "facing"):
            b[k] = b[k].float()
        positions = tensor(self.sinusoid(b["style"].shape[1], self.cfg.model.style_model_dim))
        return (b["speech"], b["style"] * self.in_scale, b["style_mask"].bool(), b["pose"], b["root_position"],
                b["root_rotation"], b["facing"], positions)

    def initial_poses(self, pose):
        """:func:`jaxgest.zeggs.steps.initial_poses` with the given swapped rows."""
        t, own = self.cfg.train, pose[:, 0]
        if t.initial_pose_shuffle <= 0.0:
            return own
        other = torch.roll(own, 1, 0) if t.initial_pose_source == "row" else torch.zeros_like(own)
        return torch.where(self.swap[:, None], other, own)

    def loss_terms(self, speech, style, style_mask, pose, root_position, root_rotation, facing, positions):
        s = self._speech(speech)
        mu, logvar = self._style(style, style_mask, positions)
        e = mu + torch.exp(0.5 * logvar) * self.eps  # style_encoder.sample_style, temperature 1
        y, p, q = self.generator(s, e, self.initial_poses(pose), root_position[:, 0], root_rotation[:, 0], facing,
                                 self.mean, self.std, self.in_scale, frame=self._frame)
        return self._losses(y, p, q, pose, root_position, root_rotation, mu, logvar, self.kl_w, self.mean,
                            self.std)

    def step(self, batch) -> dict:
        self.kl_w.fill_(kl_weight(self.steps_done, self.cfg.train))
        out = super().step(batch)
        self.steps_done += 1
        return out


__all__ = ["FFTBlock", "Losses", "SpeechEncoder", "StyleEncoder", "ZeggsStepPeer", "check_config", "kl_weight",
           "load_encoders"]

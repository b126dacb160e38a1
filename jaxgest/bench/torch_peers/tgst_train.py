"""Training-step peers of TGST in PyTorch: the autoencoder step and the style-transformer step (eqs. 5-12).

Each peer holds the authors' modules (:class:`jaxgest.bench.torch_peers.tgst.TGSTPeer`, loaded with the JAX
parameters) and ``torch.optim.Adam`` with optax's defaults (betas 0.9 / 0.999, eps 1e-8: the same update
formula as ``optax.adam``), and runs one whole step per call: forward, losses, ``backward()``, optimiser
update. ``compiled=True`` puts the loss (forward and, through AOTAutograd, backward) and the optimiser step
under ``torch.compile`` (the PyTorch recipe for compiled training on the CPU; the first call compiles).

A call returns the step's observables, the same as :func:`step_observables` of the JAX step:
``loss`` and its terms (batch means, before the update), ``grad_norm`` (global L2 norm of the gradients,
read from Adam's first moment after the first step: ``||m_1|| / (1 - beta1)``) and ``update_norm`` (global
L2 norm of the parameter change). Comparing them on the first step checks the forward, every loss weight,
the backward and the optimiser; Adam's first update is ~ ``lr sign(g)`` and would not catch a wrong loss
scale by itself, the loss and gradient norm do.

* :class:`AutoencoderStepPeer`: the paper's reconstruction loss (mean per-joint exp-map difference norm
  over all 21 joints, ``autoencoder.expmap_reconstruction_loss``) on windows replicate-padded at both
  ends and trimmed back (``model.reconstruct``); the optional recipe terms (velocity, trunk, positions)
  are not ported and refused.
* :class:`TransformerStepPeer`: eq. 12 = identity + lambda_c cyclic + lambda_s structure + lambda_a
  appearance, autoencoder frozen (tokens computed without gradient), the authors' transformer (post-LN,
  one LayerNorm per block), soft swap; ``"window"`` style tokens (no padding masks).

References: Kuriyama et al. 2022, §3.5, eqs. 5-12.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from jaxgest.bench.torch_peers.tgst import TGSTPeer, _pad_clip, load_tgst, swapper, tensor2token

BETA1 = 0.9  # optax.adam / torch.optim.Adam default


def _np(x) -> np.ndarray:
    return np.array(x, np.float32)  # a writable copy


def _norm(x, dim=-1):
    return torch.linalg.vector_norm(x, dim=dim)


class _StepPeer:
    """One optimiser step per call on fixed inputs (set by the first call); see the module docstring.

    ``optimizer``: ``"adam"`` (``optax.adam``'s defaults) or ``"radam"`` (``optax.radam``'s: the same betas and
    eps). ``compile_whole_loss = False`` in a subclass that compiles pieces of its loss itself.
    """

    compile_whole_loss = True

    def __init__(self, params: list, lr: float, compiled: bool, optimizer: str = "adam"):
        self.params = params
        kind = {"adam": torch.optim.Adam, "radam": torch.optim.RAdam}[optimizer]
        self.opt = kind(params, lr=lr, betas=(BETA1, 0.999), eps=1e-8)
        self.compiled = compiled
        self._loss = (torch.compile(self.loss_terms, dynamic=False) if compiled and self.compile_whole_loss
                      else self.loss_terms)
        self._opt_step = torch.compile(self.opt.step, dynamic=False) if compiled else self.opt.step
        self._inputs = None

    def inputs(self, batch) -> tuple:  # pragma: no cover - abstract
        raise NotImplementedError

    def loss_terms(self, *inputs) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    def step(self, batch) -> dict:
        if self._inputs is None:
            self._inputs = self.inputs(batch)
        before = [p.detach().clone() for p in self.params]
        self.opt.zero_grad(set_to_none=True)
        terms = self._loss(*self._inputs)
        terms["loss"].backward()
        self._opt_step()
        with torch.no_grad():
            m = [self.opt.state[p]["exp_avg"] for p in self.params if p in self.opt.state]
            grad_norm = torch.sqrt(sum(torch.sum(t * t) for t in m)) / (1.0 - BETA1)
            update_norm = torch.sqrt(sum(torch.sum((p - b) ** 2) for p, b in zip(self.params, before)))
        out = {k: float(v.detach()) for k, v in terms.items()}
        out.update(grad_norm=float(grad_norm), update_norm=float(update_norm))
        return out


class AutoencoderStepPeer(_StepPeer):
    """Adam step of the autoencoder (upper + lower decoders); ``step({"upper", "lower"}) -> observables``."""

    def __init__(self, cfg, params, lr: float, *, compiled: bool = False, train=None):
        if train is not None and (train.velocity_weight or train.position_velocity_weight
                                  or train.trunk_weight != 1.0):
            raise ValueError("the autoencoder step peer ports the paper's loss only (velocity, trunk and "
                             "joint-displacement terms off)")
        self.cfg = cfg
        self.peer = load_tgst(cfg, params).train()
        ps = [p for m in (self.peer.encoder, self.peer.decoder, self.peer.leg_decoder) for p in m.parameters()]
        super().__init__(ps, lr, compiled)

    def inputs(self, batch):
        return torch.from_numpy(_np(batch["upper"])), torch.from_numpy(_np(batch["lower"]))

    def loss_terms(self, upper, lower):
        cfg, f = self.cfg, upper.shape[1]
        z = self.peer.encoder(_pad_clip(upper, cfg))
        e = cfg.edge_frames
        up_hat = self.peer.decoder(z)[:, e:e + f]
        lo_hat = self.peer.leg_decoder(z)[:, e:e + f]

        def recon(pred, target):  # autoencoder.expmap_reconstruction_loss, batch mean
            b, n, c = pred.shape
            return torch.mean(_norm((pred - target).reshape(b, n, c // 3, 3)))

        return {"loss": recon(torch.cat([up_hat, lo_hat], -1), torch.cat([upper, lower], -1)),
                "upper_loss": recon(up_hat, upper), "lower_loss": recon(lo_hat, lower)}


class TransformerStepPeer(_StepPeer):
    """Adam step of the style transformer (eq. 12), autoencoder frozen; ``step({"content", "style"})``.

    ``weights``: the eq. 12 weights and switches (``TransformerTrainConfig``: ``lambda_*``, ``use_*``).
    """

    def __init__(self, cfg, params, lr: float, weights, *, compiled: bool = False):
        if weights.style_tokens != "window":
            raise ValueError("the transformer step peer ports style_tokens='window' (no padded style sets)")
        self.cfg, self.w = cfg, weights
        self.peer = load_tgst(cfg, params).train()
        ps = [p for m in (self.peer.tr_encoder, self.peer.tr_decoder) for p in m.parameters()]
        super().__init__(ps, lr, compiled)

    def inputs(self, batch):
        """Tokens ``(N, batch, w d_z)`` of the content (padded latents) and the style (its real latents)."""
        cfg = self.cfg
        w, dz, red = cfg.token_width, cfg.autoencoder.latent_dim, cfg.autoencoder.time_reduction
        with torch.no_grad():
            content, style = torch.from_numpy(_np(batch["content"])), torch.from_numpy(_np(batch["style"]))
            c_z = self.peer.encoder(_pad_clip(content, cfg))
            s_z = self.peer.encoder(_pad_clip(style, cfg))
            s0 = cfg.edge_frames // red
            s_z = s_z[:, s0:s0 + math.ceil(style.shape[1] / red)]
            return tensor2token(c_z, w, dz).contiguous(), tensor2token(s_z, w, dz).contiguous()

    def loss_terms(self, c_tok, s_tok):
        enc, dec = self.peer.tr_encoder, self.peer.tr_decoder
        t = self.w

        def swap(content_enc, style_enc, style_tok):  # eq. 3 then eq. 4
            decoded, style_rows = dec(content=content_enc, style=style_enc)
            return swapper(decoded, style_rows, style_tok)

        def token_norm(x):  # ||x||_tau over (N, batch, d) -> (batch,)
            return torch.mean(_norm(x), dim=0)

        def structure(keys):  # eq. 9
            unit = keys / torch.clamp(_norm(keys)[..., None], min=1e-8)
            return torch.einsum("bid,bjd->bij", unit, unit)

        c_enc, aux_c = enc(c_tok, return_aux=True)
        s_enc, aux_s = enc(s_tok, return_aux=True)
        transferred = swap(c_enc, s_enc, s_tok)
        zeros = torch.zeros(c_tok.shape[1])
        terms = {"identity": zeros, "cyclic": zeros, "structure": zeros, "appearance": zeros}
        if t.use_identity:  # eq. 5
            terms["identity"] = token_norm(swap(c_enc, c_enc, c_tok) - c_tok) + \
                token_norm(swap(s_enc, s_enc, s_tok) - s_tok)
        if t.use_cyclic or t.use_structure or t.use_appearance:
            x_enc, aux_x = enc(transferred, return_aux=True)
            if t.use_cyclic:  # eqs. 6-8
                terms["cyclic"] = token_norm(swap(x_enc, c_enc, c_tok) - c_tok)
            if t.use_structure:  # eq. 10
                d = structure(aux_c["keys"]) - structure(aux_x["keys"])
                terms["structure"] = _norm(d.reshape(d.shape[0], -1))
            if t.use_appearance:  # eq. 11
                terms["appearance"] = _norm(aux_s["cls"] - aux_x["cls"])
        loss = sum(lam * terms[k] for k, lam, on in (
            ("identity", t.lambda_identity, t.use_identity), ("cyclic", t.lambda_cyclic, t.use_cyclic),
            ("structure", t.lambda_structure, t.use_structure),
            ("appearance", t.lambda_appearance, t.use_appearance)) if on)
        out = {k: torch.mean(v) for k, v in terms.items()}
        out["loss"] = torch.mean(loss)
        return out


def step_call(peer: _StepPeer):
    """``f(*harness_args) -> observables``: the harness calling convention (the batch is ``args[1]``)."""

    def run(_state, batch, *_rest):
        return peer.step(batch)

    return run


__all__ = ["AutoencoderStepPeer", "TGSTPeer", "TransformerStepPeer", "step_call"]

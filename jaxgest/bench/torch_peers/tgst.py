"""TGST (:class:`TGSTPeer`): the network as the authors wrote it (``nn/autoencoder.py``, ``nn/transformer.py``,
``nn/gsxf.py`` of their public code): ``Encoder`` (Conv1d k1 / k3 s2 / k3 s2, GELU), the two ``Decoder``\\ s
(Upsample x2 linear, ConvTranspose1d k3 p1, GELU, ..., ConvTranspose1d k1), ``TransformerEncoder``
(CLS token, constant positional table added along the batch axis, ONE LayerNorm per block used before the
attention and after both residuals -- post-LN --, fused ``fc_qkv``, the dense 2560 x 2560 band mask with
``masked_fill(-1e10)``), ``TransformerDecoder`` (shared LayerNorm, ``fc_q`` and fused ``fc_kv``) and the
multi-stream soft ``swapper``, in the authors' ``(tokens, batch, dim)`` layout with their
``tensor2token``. The glue follows jaxgest so the outputs are comparable: both clips are replicate-padded
by ``edge_frames`` at both ends (docs/design.md §3), the style latents are cut to the real clip, and the tokens are
merged back with jaxgest's per-frame linear cross-fade (:func:`jaxgest.tgst.tokens.detokenize`; the
authors' ``linear_blending`` ramps over the 32 flattened values of a half token instead). The JAX side of
the comparison runs ``transformer.variant="authors"`` (the same network).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn as nn

from jaxgest.bench.torch_peers.common import tensor


# --------------------------------------------------------------------------------------------------------
# TGST: the authors' modules
# --------------------------------------------------------------------------------------------------------
class Encoder(nn.Module):
    """``nn/autoencoder.py`` Encoder: (batch, frames, 39) -> (batch, frames / 4, 16)."""

    def __init__(self, input_channel, channels):
        super().__init__()
        self.layers = nn.Sequential(
            nn.Conv1d(in_channels=input_channel, out_channels=channels[0], kernel_size=1, padding=0, stride=1),
            nn.GELU(),
            nn.Conv1d(in_channels=channels[0], out_channels=channels[1], kernel_size=3, padding=1, stride=2),
            nn.GELU(),
            nn.Conv1d(in_channels=channels[1], out_channels=channels[2], kernel_size=3, padding=1, stride=2),
            nn.GELU(),
        )

    def forward(self, z):
        return self.layers(z.transpose(1, 2)).transpose(1, 2)


class Decoder(nn.Module):
    """``nn/autoencoder.py`` Decoder: (batch, T, 16) -> (batch, 4 T, output_channel)."""

    def __init__(self, output_channel, channels):
        super().__init__()
        self.layers = nn.Sequential(
            nn.Upsample(scale_factor=2, mode="linear", align_corners=False),
            nn.ConvTranspose1d(in_channels=channels[0], out_channels=channels[1], kernel_size=3, padding=1),
            nn.GELU(),
            nn.Upsample(scale_factor=2, mode="linear", align_corners=False),
            nn.ConvTranspose1d(in_channels=channels[1], out_channels=channels[2], kernel_size=3, padding=1),
            nn.GELU(),
            nn.ConvTranspose1d(in_channels=channels[2], out_channels=output_channel, kernel_size=1, padding=0),
        )

    def forward(self, z):
        return self.layers(z.transpose(1, 2)).transpose(1, 2)


class ConstantPE(nn.Module):
    """``nn/transformer.py`` ConstantPE (angle 2 pi pos f; added along dim 0 after the authors' transpose)."""

    def __init__(self, d_model, max_len, period=1):
        super().__init__()
        pe = torch.zeros(max_len, d_model)
        position = 2.0 * np.pi * torch.arange(0, max_len, dtype=torch.float).unsqueeze(1) / period
        div_term = torch.exp(torch.arange(0, d_model, 2) * (-torch.log(torch.tensor(10000.0)) / d_model))
        pe[:, 0::2] = torch.sin(position * div_term)
        pe[:, 1::2] = torch.cos(position * div_term)
        self.register_buffer("pe", pe.unsqueeze(0))

    def forward(self, z):
        _z = z.transpose(0, 1)
        return (_z + self.pe[:, :_z.size(1), :]).transpose(0, 1)


class TransformerEncoder(nn.Module):
    """``nn/transformer.py`` TransformerEncoder: tokens (N, batch, d) -> encoded (1 + N, batch, d)."""

    def __init__(self, hid_dim, mask_range=20, mask_size=2560):
        super().__init__()
        # the authors fill this mask row by row in a Python loop; the same values, vectorised
        rows = torch.arange(mask_size)[:, None]
        cols = torch.arange(mask_size)[None, :]
        band = (cols >= (rows - mask_range).clamp(min=0)) & (cols < (rows + mask_range).clamp(max=mask_size))
        self.src_mask = ~(band | (rows == 0))  # 1 = masked
        self.pe = ConstantPE(d_model=hid_dim, max_len=150)
        self.layer_nrm = nn.LayerNorm(normalized_shape=hid_dim)
        self.fc_qkv = nn.Linear(hid_dim, 3 * hid_dim)
        self.fc_o = nn.Linear(hid_dim, hid_dim)
        self.scale = torch.sqrt(torch.tensor([hid_dim], dtype=torch.float))
        self.mlp = nn.Sequential(nn.Linear(hid_dim, hid_dim), nn.GELU(), nn.Linear(hid_dim, hid_dim))
        self.cls_token = nn.Parameter(torch.randn(1, hid_dim))

    def forward(self, z, return_aux: bool = False):
        """``return_aux``: also ``{"keys": (batch, N, d), "cls": (batch, d)}`` (the structure and appearance
        losses' inputs; CLS excluded from the keys)."""
        _z = z.transpose(0, 1)
        _cls_tokens = self.cls_token.repeat(_z.shape[0], 1, 1)
        _z = torch.cat((_cls_tokens, _z), dim=1)
        _z = self.layer_nrm(self.pe(_z))
        (query, key, value) = self.fc_qkv(_z).chunk(3, dim=-1)
        attn = torch.matmul(query, key.transpose(1, 2)) / self.scale
        _size = z.shape[0] + 1
        attn = attn.masked_fill(self.src_mask[:_size, :_size] == 1, -1e10)
        attn = torch.softmax(attn, dim=-1)
        _sa = self.fc_o(torch.matmul(attn, value))
        _zsa = self.layer_nrm(_z + _sa)
        out = (_zsa + self.mlp(_zsa)).transpose(0, 1)
        return (out, {"keys": key[:, 1:], "cls": out[0]}) if return_aux else out


class TransformerDecoder(nn.Module):
    """``nn/transformer.py`` TransformerDecoder: cross-attention of content over style (CLS rows dropped)."""

    def __init__(self, hid_dim):
        super().__init__()
        self.layer_nrm = nn.LayerNorm(normalized_shape=hid_dim)
        self.fc_q = nn.Linear(hid_dim, hid_dim)
        self.fc_kv = nn.Linear(hid_dim, 2 * hid_dim)
        self.fc_o = nn.Linear(hid_dim, hid_dim)
        self.scale = torch.sqrt(torch.tensor([hid_dim], dtype=torch.float))
        self.mlp = nn.Sequential(nn.Linear(hid_dim, hid_dim), nn.GELU(), nn.Linear(hid_dim, hid_dim))

    def forward(self, content, style):
        _content, _style = content[1:, :, :], style[1:, :, :]
        _z = self.layer_nrm(_content.transpose(0, 1))
        query = self.fc_q(_z)
        _zs = self.layer_nrm(_style.transpose(0, 1))
        (key, value) = self.fc_kv(_zs).chunk(2, dim=-1)
        dot_prod = torch.matmul(query, key.transpose(1, 2)) / self.scale
        _weight = torch.softmax(dot_prod, dim=-1)
        _xa = self.fc_o(torch.matmul(_weight, value))
        _zxa = self.layer_nrm(_z + _xa)
        return (_zxa + self.mlp(_zxa)).transpose(0, 1), _style


def swapper(decoded_content, encoded_style, style_token):
    """``nn/gsxf.py`` swapper, ``multi_stream=True`` (each batch element swaps with its own style)."""
    _matrix = torch.einsum("ibk,jbk->bij", decoded_content, encoded_style)
    _weights = torch.softmax(_matrix, dim=2)
    return torch.einsum("bij,jbk->bik", _weights, style_token).transpose(0, 1)


def tensor2token(tensor, token_width, dim_z):
    """``nn/gsxf.py`` GestureStyleTransformer.tensor2token: (batch, T, d_z) -> (N, batch, w d_z)."""
    _num_token = int(tensor.shape[1] // token_width)
    _step = token_width // 2
    _n_batch = tensor.shape[0]
    _n_split = int(token_width // _step)
    _total = (_num_token - 1) * _n_split + 1
    _token_dim = token_width * dim_z
    _tens_pool = torch.zeros(_n_batch, _total, _token_dim)
    for offset, s in enumerate(range(0, token_width, _step)):
        if s == 0:
            _tens = tensor[:, :_num_token * token_width, :]
            _tens_pool[:, 0::_n_split] = torch.reshape(_tens, (_n_batch, _num_token, _token_dim))
        else:
            _tens = tensor[:, s:(_num_token - 1) * token_width + s, :]
            _tens_pool[:, offset::_n_split] = torch.reshape(_tens, (_n_batch, _num_token - 1, _token_dim))
    return _tens_pool.transpose(0, 1)


def crossfade(tokens, length, w, h):
    """jaxgest's per-frame cross-fade (:func:`jaxgest.tgst.tokens.detokenize`): (N, batch, w d) -> latents."""
    tokens = tokens.transpose(0, 1)
    b, n, dg = tokens.shape
    d = dg // w
    halves = tokens.reshape(b, n, 2, h, d)
    first, second = halves[:, :, 0], halves[:, :, 1]
    a = (torch.arange(1, h + 1, dtype=tokens.dtype) / (h + 1))[None, None, :, None]
    middle = (1.0 - a) * second[:, :-1] + a * first[:, 1:]
    chunks = torch.cat([first[:, :1], middle, second[:, -1:]], dim=1)
    return chunks.reshape(b, (n + 1) * h, d)[:, :length]


class TGSTPeer(nn.Module):
    """Autoencoder + style transformer of the authors; ``forward(content, style) -> (upper, lower)``."""

    def __init__(self, cfg):
        super().__init__()
        a, t = cfg.autoencoder, cfg.transformer
        if (tuple(a.encoder_kernels), tuple(a.encoder_strides), tuple(a.decoder_kernels),
                tuple(a.decoder_upsample), a.standardize) != ((1, 3, 3), (1, 2, 2), (3, 3, 1), (2, 2, 1), False):
            raise ValueError("the PyTorch peer is the authors' architecture (the paper preset's autoencoder)")
        if t.variant != "authors" or t.layernorms_per_block != 1 or cfg.swap_similarity != "dot" \
                or cfg.swap_temperature != 1.0:
            raise ValueError("compare the PyTorch peer with transformer.variant='authors' (one LN per block) "
                             "and the plain dot-product swap")
        self.cfg = cfg
        self.encoder = Encoder(a.upper_channels, a.encoder_channels)
        self.decoder = Decoder(a.upper_channels, (a.latent_dim,) + tuple(a.upper_decoder_channels))
        self.leg_decoder = Decoder(a.lower_channels, (a.latent_dim,) + tuple(a.lower_decoder_channels))
        self.tr_encoder = TransformerEncoder(t.token_dim, mask_range=t.omega)
        self.tr_decoder = TransformerDecoder(t.token_dim)

    def forward(self, content, style):
        cfg = self.cfg
        w, h, dz = cfg.token_width, cfg.token_stride, cfg.autoencoder.latent_dim
        red = cfg.autoencoder.time_reduction
        fc, fs = content.shape[1], style.shape[1]
        if fs % (red * w):
            raise ValueError(f"style clip of {fs} frames: the authors' tensor2token drops a tail that is not a "
                             f"whole token; use a multiple of {red * w} frames")
        c_z = self.encoder(_pad_clip(content, cfg))
        s_z = self.encoder(_pad_clip(style, cfg))
        s0 = cfg.edge_frames // red
        s_z = s_z[:, s0:s0 + math.ceil(fs / red)]
        c_token, s_token = tensor2token(c_z, w, dz), tensor2token(s_z, w, dz)
        c_enc, s_enc = self.tr_encoder(c_token), self.tr_encoder(s_token)
        c_dec, s_encoded = self.tr_decoder(content=c_enc, style=s_enc)
        xf = swapper(c_dec, s_encoded, s_token)
        z = crossfade(xf, c_z.shape[1], w, h)
        e = cfg.edge_frames
        return self.decoder(z)[:, e:e + fc], self.leg_decoder(z)[:, e:e + fc]


def _pad_clip(x, cfg):
    """jaxgest's clip-end padding (:func:`jaxgest.tgst.model.pad_clip`): replicate the edge frames."""
    f = x.shape[1]
    lead = cfg.edge_frames
    m = cfg.frame_multiple
    total = int(math.ceil((f + 2 * lead) / m) * m)
    if total == f:
        return x
    idx = torch.clamp(torch.arange(total) - lead, 0, f - 1)
    return x[:, idx]


def load_tgst(cfg, params) -> TGSTPeer:
    """A :class:`TGSTPeer` holding the JAX parameters ``{"autoencoder", "transformer"}`` (float32 copies)."""
    peer = TGSTPeer(cfg).eval()
    ae, tr = params["autoencoder"], params["transformer"]

    def conv(mod, k, b):  # flax (k, in, out) -> Conv1d (out, in, k)
        mod.weight.copy_(tensor(np.asarray(k).transpose(2, 1, 0)))
        mod.bias.copy_(tensor(b))

    def conv_t(mod, k, b):  # flax (k, in, out) -> ConvTranspose1d (in, out, k) of the flipped kernel
        mod.weight.copy_(tensor(np.asarray(k)[::-1].transpose(1, 2, 0)))
        mod.bias.copy_(tensor(b))

    def lin(mod, *denses):  # flax Dense kernels (in, out) concatenated along out -> Linear (out, in)
        mod.weight.copy_(tensor(np.concatenate([np.asarray(d["kernel"]) for d in denses], axis=1).T))
        mod.bias.copy_(tensor(np.concatenate([np.asarray(d["bias"]) for d in denses])))

    def ln(mod, p):
        mod.weight.copy_(tensor(p["scale"]))
        mod.bias.copy_(tensor(p["bias"]))

    with torch.no_grad():
        enc = ae["encoder"]
        for i, layer in enumerate((0, 2, 4)):
            conv(peer.encoder.layers[layer], enc[f"conv_{i}"]["kernel"], enc[f"conv_{i}"]["bias"])
        for mod, name in ((peer.decoder, "upper_decoder"), (peer.leg_decoder, "lower_decoder")):
            for i, layer in enumerate((1, 4, 6)):
                conv_t(mod.layers[layer], ae[name][f"conv_{i}"]["kernel"], ae[name][f"conv_{i}"]["bias"])
        e, d = tr["encoder"], tr["decoder"]
        ln(peer.tr_encoder.layer_nrm, e["ln"])
        lin(peer.tr_encoder.fc_qkv, e["query"], e["key"], e["value"])
        lin(peer.tr_encoder.fc_o, e["out"])
        lin(peer.tr_encoder.mlp[0], e["mlp"]["fc_0"])
        lin(peer.tr_encoder.mlp[2], e["mlp"]["fc_1"])
        peer.tr_encoder.cls_token.copy_(tensor(np.asarray(e["cls"])[None]))
        ln(peer.tr_decoder.layer_nrm, d["ln"])
        lin(peer.tr_decoder.fc_q, d["query"])
        lin(peer.tr_decoder.fc_kv, d["key"], d["value"])
        lin(peer.tr_decoder.fc_o, d["out"])
        lin(peer.tr_decoder.mlp[0], d["mlp"]["fc_0"])
        lin(peer.tr_decoder.mlp[2], d["mlp"]["fc_1"])
    return peer


def tgst_call(peer: TGSTPeer):
    """``f(params, content, style) -> (upper, lower)`` NumPy in/out, the harness's calling convention."""

    def run(_params, content, style):
        with torch.inference_mode():
            up, lo = peer(torch.from_numpy(np.array(content)), torch.from_numpy(np.array(style)))
        return up.numpy(), lo.numpy()

    return run

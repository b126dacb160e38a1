"""``torch.compile`` variants of the PyTorch peers: what an ML engineer reaches for to speed PyTorch up.

Inductor (the default backend) generates fused C++/OpenMP kernels on the CPU. The first call of a compiled
peer traces and compiles (the harness times it as ``compile_s``, ``Impl(kind="compiled")``); later calls
run the cached kernels. Modes: ``"default"`` and ``"max-autotune-no-cudagraphs"`` (autotunes GEMM
templates; on the CPU it is much slower to compile).

* TGST: the whole :class:`~jaxgest.bench.torch_peers.tgst.TGSTPeer` forward is one graph (fixed shapes);
* ZeroEGGS: the per-frame step (:meth:`~jaxgest.bench.torch_peers.zeggs.ZeggsPeer.frame`) is compiled and
  the frame loop stays in Python, as the official ``Decoder.forward`` loops (compiling the whole loop
  would unroll it once per generated frame).

Inductor compiles the OpenMP thread count into its kernels, so a compiled peer is built (and compiled)
after :func:`~jaxgest.bench.torch_peers.common.set_threads`, once per thread setting.
"""

from __future__ import annotations

import numpy as np
import torch

from jaxgest.bench.torch_peers.zeggs import ZeggsPeer, zeggs_call

MODES = ("default", "max-autotune-no-cudagraphs")


def compile_fn(fn, mode: str = "default"):
    """``torch.compile(fn)`` with static shapes (every case has fixed shapes) and ``mode``."""
    if mode not in MODES:
        raise ValueError(f"unknown torch.compile mode {mode!r} (expected one of {MODES})")
    return torch.compile(fn, mode=None if mode == "default" else mode, dynamic=False)


def tgst_compiled_call(peer, mode: str = "default"):
    """As :func:`jaxgest.bench.torch_peers.tgst.tgst_call`, on ``torch.compile(peer)``."""
    compiled = compile_fn(peer, mode)

    def run(_params, content, style):
        with torch.inference_mode():
            up, lo = compiled(torch.from_numpy(np.array(content)), torch.from_numpy(np.array(style)))
        return up.numpy(), lo.numpy()

    return run


def zeggs_compiled_call(peer: ZeggsPeer, in_scale: np.ndarray, mode: str = "default"):
    """As :func:`jaxgest.bench.torch_peers.zeggs.zeggs_call`, with the per-frame step compiled."""
    return zeggs_call(peer, in_scale, frame=compile_fn(peer.frame, mode))

"""Eager PyTorch peers of the two models, loaded with the SAME weights as the JAX models (``[bench]`` extra).

This module imports ``torch`` at the top: only the benchmark suite imports it, and only when torch is
installed (:func:`available`); ``jaxgest`` itself never does.

TGST: :mod:`jaxgest.bench.torch_peers.tgst` (:class:`TGSTPeer`, the authors' network); ZeroEGGS:
:mod:`jaxgest.bench.torch_peers.zeggs` (:class:`ZeggsPeer`, the official generator).

Both run under ``torch.inference_mode()`` in float32 on the CPU with ``torch.set_num_threads`` set by the
caller (:func:`set_threads`).
"""

from __future__ import annotations

from jaxgest.bench.torch_peers import compiled  # noqa: F401  (torch.compile variants)
from jaxgest.bench.torch_peers.common import set_threads
from jaxgest.bench.torch_peers.tgst import TGSTPeer, load_tgst, tgst_call
from jaxgest.bench.torch_peers.zeggs import ZeggsPeer, load_zeggs, zeggs_call

__all__ = ["compiled", "TGSTPeer", "ZeggsPeer", "load_tgst", "load_zeggs", "set_threads", "tgst_call", "zeggs_call"]

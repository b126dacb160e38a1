"""The ZeroEGGS authors' released speech encoders (PyTorch) as jaxgest parameters.

The authors' repository releases, for v1 and v2, ``data/outputs/<v>/saved_models/speech_encoder.pt``: a
whole pickled ``modules.SpeechEncoder`` with ``layer0`` Conv1d 81->64 (kernel 1), ``layer1`` Conv1d 64->64
(kernel 31), both "same"-padded with replicated edges, and ``layer2`` Linear 64->64, each followed by ELU
(dropout between, off at inference). jaxgest's :class:`jaxgest.zeggs.speech_encoder.SpeechEncoder` is the same
network for a :class:`~jaxgest.zeggs.config.ModelConfig` with ``speech_channels=(64, 64)``,
``speech_kernels=(1, 31)`` and ``speech_embedding=64`` (:func:`released_speech_config`); its input is the
authors' speech features (``jaxgest.audio.speech_features(method="authors")``) normalised with the release's
``stats.npz`` (``audio_input_mean``, ``audio_input_std``), as their ``generate.py`` does.

:func:`speech_encoder_params` maps a state dict (NumPy arrays, or tensors) or a torch module to the Flax
parameters: a torch Conv1d weight ``(out, in, k)`` becomes a Flax Conv kernel ``(k, in, out)``, a torch Linear
weight ``(out, in)`` a Dense kernel ``(in, out)``; biases are copied. A missing or extra entry, a wrong shape
or a non-finite value is a one-line :class:`~jaxgest.runtime.errors.CheckpointError` naming the layer.
Nothing here imports torch except :func:`load_torch_speech_encoder`, which unpickles a released ``.pt``.

References: Ghorbani et al. 2023, §3.1, §4.2; the authors' ``ZEGGS/modules.py`` (``SpeechEncoder``) and
``ZEGGS/generate.py`` (loading and normalising); docs/design.md §4.
"""

from __future__ import annotations

import pathlib
from typing import Any, Mapping, Optional

import numpy as np

from jaxgest.runtime.errors import CheckpointError
from jaxgest.zeggs.authors_path import their_code_on_path
from jaxgest.zeggs.config import ModelConfig

#: The released encoders' sizes (both v1 and v2).
RELEASED = dict(speech_channels=(64, 64), speech_kernels=(1, 31), speech_embedding=64)


def released_speech_config(base: Optional[ModelConfig] = None) -> ModelConfig:
    """``base`` (default: the default ModelConfig) with the released speech encoder's sizes and the authors'
    speech features."""
    return (base or ModelConfig()).replace(**RELEASED, speech_features="authors")


def _array(value: Any) -> np.ndarray:
    """A NumPy copy of an array or a (CPU or GPU) tensor, without importing torch."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value)


def expected_shapes(cfg: ModelConfig) -> dict[str, tuple[int, ...]]:
    """The authors' state-dict entries and their (PyTorch) shapes for the speech encoder of ``cfg``."""
    shapes, cin = {}, cfg.speech_dim
    for i, (ch, k) in enumerate(zip(cfg.speech_channels, cfg.speech_kernels)):
        shapes[f"layer{i}.weight"], shapes[f"layer{i}.bias"] = (ch, cin, k), (ch,)
        cin = ch
    n = len(cfg.speech_channels)
    shapes[f"layer{n}.weight"], shapes[f"layer{n}.bias"] = (cfg.speech_embedding, cin), (cfg.speech_embedding,)
    return shapes


def speech_encoder_params(source: Any, cfg: Optional[ModelConfig] = None, *, name: str = "state dict") -> dict:
    """Flax parameters of :class:`jaxgest.zeggs.speech_encoder.SpeechEncoder` (``{"conv0", "conv1",
    "linear"}``, float32; what ``params["speech_encoder"]`` of a jaxgest ZeroEGGS model holds) from the authors'
    speech encoder: a mapping ``{"layer0.weight": ..., ...}`` of arrays or tensors, or a torch module (its
    ``state_dict()``). ``cfg``: the model config whose sizes the weights must have (default:
    :func:`released_speech_config`). ``name`` names the source in errors (e.g. the ``.pt`` path)."""
    cfg = cfg or released_speech_config()
    if hasattr(source, "state_dict") and callable(source.state_dict):
        source = source.state_dict()
    if not isinstance(source, Mapping):
        raise CheckpointError(f"{name}: not a speech encoder state dict or module ({type(source).__name__})")
    want = expected_shapes(cfg)
    missing = [k for k in want if k not in source]
    extra = sorted(k for k in source if k not in want)
    if missing or extra:
        what = "; ".join(x for x in (f"missing {', '.join(missing)}" if missing else "",
                                     f"unexpected {', '.join(extra[:4])}" if extra else "") if x)
        raise CheckpointError(f"{name}: not the authors' SpeechEncoder for speech_channels={cfg.speech_channels}, "
                              f"speech_kernels={cfg.speech_kernels} ({what})")
    arrays = {}
    for key, shape in want.items():
        a = _array(source[key])
        if a.shape != shape:
            raise CheckpointError(f"{name}: {key} has shape {a.shape}, expected {shape} (layer "
                                  f"{key.split('.')[0]} of speech_channels={cfg.speech_channels}, "
                                  f"speech_kernels={cfg.speech_kernels}, speech_embedding={cfg.speech_embedding})")
        if not np.all(np.isfinite(a)):
            raise CheckpointError(f"{name}: parameter {key} contains NaN or inf")
        arrays[key] = a.astype(np.float32)
    params = {}
    n = len(cfg.speech_channels)
    for i in range(n):
        params[f"conv{i}"] = {"kernel": np.ascontiguousarray(arrays[f"layer{i}.weight"].transpose(2, 1, 0)),
                              "bias": arrays[f"layer{i}.bias"]}
    params["linear"] = {"kernel": np.ascontiguousarray(arrays[f"layer{n}.weight"].T), "bias": arrays[f"layer{n}.bias"]}
    return params


def load_torch_speech_encoder(path, code_dir) -> dict:
    """Parameters (:func:`speech_encoder_params`) of a released ``speech_encoder.pt``: a whole pickled module,
    unpickled with the authors' ``ZEGGS/`` folder ``code_dir`` on ``sys.path`` (only for this call). Needs
    torch; unpickling runs code from the file, so load only files you trust (the authors' release)."""
    path, code_dir = pathlib.Path(path), pathlib.Path(code_dir)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such file")
    if not (code_dir / "modules.py").is_file():
        raise CheckpointError(f"{code_dir}: not the authors' ZEGGS folder (no modules.py), needed to unpickle {path}")
    try:
        import torch
    except ImportError:
        raise CheckpointError(f"{path}: reading a PyTorch file needs torch (pip install 'jaxgest[authors]')") from None
    try:
        with their_code_on_path(code_dir):  # the authors' modules (e.g. "modules", "audio") leave with their path
            module = torch.load(str(path), map_location="cpu", weights_only=False)
            return speech_encoder_params(module, name=str(path))
    except CheckpointError:
        raise
    except Exception as e:  # unpickling errors have many types
        raise CheckpointError(f"{path}: unreadable PyTorch file ({type(e).__name__}: "
                              f"{str(e).splitlines()[0][:120] if str(e) else ''})") from None

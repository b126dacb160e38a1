"""ZeroEGGS user-facing API (SPEC §7): ``generate``, ``load_model``, ``count_params`` and ``ModelCache``.

``generate(audio, styles, *, workdir, weights=None, seed=0, temperature=1.0) -> Motion`` is what
``jaxgest zeggs generate`` calls: gestures for a speech file (path or ``(samples, sr)``) in the style of
one example clip or a weighted blend of several (Motions or BVH paths), on the first style clip's skeleton
with ``round(duration * fps)`` frames at its frame rate. It reuses loaded models through
:data:`MODEL_CACHE`, an explicit :class:`ModelCache` keyed on the workdir and its newest checkpoint step
(``cache=None`` reads the workdir every call).

References: Ghorbani et al. 2023, §3 (zero-shot style from an example clip), §5.2.1 (blending), Table 2
(about 25 M parameters).
"""

from __future__ import annotations

import os
import pathlib
from typing import Optional, Sequence, Union

import jax
import numpy as np

from jaxgest.runtime import model_cache
from jaxgest.runtime.errors import JaxgestError
from jaxgest.motion import bvh
from jaxgest.motion.skeleton import Motion
from jaxgest.zeggs.config import Config, ModelConfig, preset as get_preset
from jaxgest.zeggs.inference import TrainedZeggs, load_model
from jaxgest.zeggs.model import param_shapes
from jaxgest.zeggs.workdir import CKPT_SUBDIR, latest_step

__all__ = ["count_params", "generate", "load_model", "ModelCache", "MODEL_CACHE", "TrainedZeggs"]

StyleLike = Union[Motion, str, os.PathLike]


def _as_motions(styles) -> list[Motion]:
    if isinstance(styles, (Motion, str, os.PathLike)):
        styles = [styles]
    out = []
    for s in styles:
        if isinstance(s, Motion):
            out.append(s)
        elif isinstance(s, (str, os.PathLike)):
            out.append(bvh.load(s))
        else:
            raise JaxgestError(f"a style must be a Motion or a BVH path, got {type(s).__name__}")
    if not out:
        raise JaxgestError("at least one style clip is needed")
    return out


class ModelCache(model_cache.ModelCache):
    """Loaded ZeroEGGS models (:class:`jaxgest.runtime.model_cache.ModelCache`), keyed on the workdir, its newest
    checkpoint step and that step folder's modification time: a run that trains further (a new step) or is
    retrained into the same workdir (a rewritten step folder) is loaded again."""

    def __init__(self, maxsize: int = 2):
        super().__init__(load_model, _newest_checkpoint, maxsize)


def _newest_checkpoint(workdir) -> tuple:
    workdir = pathlib.Path(workdir).resolve()
    step = latest_step(workdir)
    folder = workdir / CKPT_SUBDIR / str(step)
    return step, folder.stat().st_mtime_ns if step is not None else None


MODEL_CACHE = ModelCache()  # what generate() uses by default


def generate(audio, styles: Union[StyleLike, Sequence[StyleLike]], *, workdir,
             weights: Optional[Sequence[float]] = None, seed: int = 0, temperature: float = 1.0,
             pca_edits: Optional[dict] = None, normalize_weights: bool = False,
             cache: Optional[ModelCache] = MODEL_CACHE, weight_format: str = "fp32") -> Motion:
    """Gestures for ``audio`` (a WAV/FLAC path, or ``(samples, sample_rate)``) in the style of ``styles``.

    ``styles``: one Motion or BVH path, or a list of them, blended as ``sum_i w_i e_i`` with ``weights``
    as given (one per clip, finite; default ``1 / n`` each; (2, 0) gives twice the first embedding);
    ``normalize_weights=True`` divides them by their sum (which must be positive). ``seed`` and
    ``temperature`` drive the style-embedding sample;
    ``pca_edits`` ``{component: delta in std}`` needs ``workdir/pca.json`` (``jaxgest zeggs pca``).
    ``cache``: where loaded models are kept (:class:`ModelCache`; None: load the workdir now).
    ``weight_format`` (``"fp32"`` | ``"bf16"`` | ``"int8"``): the generator's weight format (not the
    blend ``weights``), see :mod:`jaxgest.zeggs.quant`.
    Returns a Motion on the first style clip's skeleton at its frame rate, ``round(duration * fps)`` frames.
    References: Ghorbani et al. 2023, §3, §5.2.
    """
    sr = None
    if isinstance(audio, tuple):
        if len(audio) != 2:
            raise JaxgestError("audio must be a path or a (samples, sample_rate) pair")
        audio, sr = np.asarray(audio[0], np.float32), int(audio[1])
    elif isinstance(audio, (str, os.PathLike)) and not pathlib.Path(audio).is_file():
        raise JaxgestError(f"{audio}: no such audio file")
    elif not isinstance(audio, (str, os.PathLike)):
        raise JaxgestError("audio must be a path or a (samples, sample_rate) pair")
    model = load_model(workdir) if cache is None else cache.get(workdir)
    return model.generate(audio, _as_motions(styles), weights=weights, seed=seed, temperature=temperature,
                          pca_edits=pca_edits, sr=sr, normalize_weights=normalize_weights,
                          weight_format=weight_format)


def count_params(preset: str | Config | ModelConfig = "paper") -> dict[str, int]:
    """Parameters of a freshly initialised model: ``{"speech_encoder", "style_encoder", "generator"}``.

    Shapes only (``jax.eval_shape``): nothing is allocated. The paper preset assumes the paper's 75-joint
    rig, pose vector 15 * 75 + 6 = 1131 channels.
    """
    cfg = get_preset(preset) if isinstance(preset, str) else preset
    shapes = param_shapes(cfg.model if isinstance(cfg, Config) else cfg)
    return {name: int(sum(np.prod(x.shape) for x in jax.tree_util.tree_leaves(shapes[name])))
            for name in ("speech_encoder", "style_encoder", "generator")}

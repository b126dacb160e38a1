"""ZeroEGGS user-facing API (docs/design.md §7): ``load``, ``generate`` and ``count_params``.

``load(workdir) -> TrainedZeggs`` reads a trained workdir; ``model.generate(audio, styles, weights=...,
seed=...)`` makes gestures with it (:mod:`jaxgest.zeggs.inference`). The model owns its compiled
functions: keep it to generate again without compiling again.

``generate(audio, styles, *, workdir, weights=None, seed=0, temperature=1.0) -> Motion`` is what
``jaxgest zeggs generate`` calls: it loads ``workdir`` on every call and generates once. ``audio``: a
speech file path or ``(samples, sr)``; ``styles``: one example clip or a weighted blend of several (Motions
or BVH paths). The result is on the first style clip's skeleton with ``round(duration * fps)`` frames at
its frame rate.

References: Ghorbani et al. 2023, §3 (zero-shot style from an example clip), §5.2.1 (blending), Table 2
(about 25 M parameters).
"""

from __future__ import annotations

from typing import Optional, Sequence, Union

import jax
import numpy as np

from jaxgest.motion.skeleton import Motion
from jaxgest.zeggs.config import Config, ModelConfig, preset as get_preset
from jaxgest.zeggs.inference import StyleLike, TrainedZeggs, as_motions, audio_input, load, load_model
from jaxgest.zeggs.model import param_shapes

__all__ = ["count_params", "generate", "load", "load_model", "TrainedZeggs"]


def generate(audio, styles: Union[StyleLike, Sequence[StyleLike]], *, workdir,
             weights: Optional[Sequence[float]] = None, seed: int = 0, temperature: float = 1.0,
             pca_edits: Optional[dict] = None, normalize_weights: bool = False,
             weight_format: str = "fp32") -> Motion:
    """Gestures for ``audio`` (a WAV/FLAC path, or ``(samples, sample_rate)``) in the style of ``styles``,
    with the model of ``workdir`` loaded now (:func:`load`, then :meth:`TrainedZeggs.generate`).

    ``styles``: one Motion or BVH path, or a list of them, blended as ``sum_i w_i e_i`` with ``weights``
    as given (one per clip, finite; default ``1 / n`` each; (2, 0) gives twice the first embedding);
    ``normalize_weights=True`` divides them by their sum (which must be positive). ``seed`` and
    ``temperature`` drive the style-embedding sample;
    ``pca_edits`` ``{component: delta in std}`` needs ``workdir/pca.json`` (``jaxgest zeggs pca``).
    ``weight_format`` (``"fp32"`` | ``"bf16"`` | ``"int8"``): the generator's weight format (not the
    blend ``weights``), see :mod:`jaxgest.zeggs.quant`.
    Returns a Motion on the first style clip's skeleton at its frame rate, ``round(duration * fps)`` frames.
    References: Ghorbani et al. 2023, §3, §5.2.
    """
    from jaxgest.zeggs.official import is_official

    audio, sr = audio_input(audio)  # checked before the workdir is read
    if not is_official(workdir):  # an imported label-based release takes label names
        styles = as_motions(styles)
    return load(workdir).generate(audio, styles, weights=weights, seed=seed, temperature=temperature,
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

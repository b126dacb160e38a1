"""ZeroEGGS user-facing API (SPEC §7): ``generate``, ``load_model`` and ``count_params``.

``generate(audio, styles, *, workdir, weights=None, seed=0, temperature=1.0) -> Motion`` is what
``jaxgest zeggs generate`` calls: gestures for a speech file (path or ``(samples, sr)``) in the style of
one example clip or a weighted blend of several (Motions or BVH paths), on the first style clip's skeleton
with ``round(duration * fps)`` frames at its frame rate.

References: Ghorbani et al. 2023, §3 (zero-shot style from an example clip), §5.2.1 (blending), Table 2
(about 25 M parameters).
"""

from __future__ import annotations

import os
import pathlib
from typing import Optional, Sequence, Union

import jax
import numpy as np

from jaxgest.errors import JaxgestError
from jaxgest.motion import bvh
from jaxgest.motion.skeleton import Motion
from jaxgest.zeggs.config import ZeggsConfig, get_config
from jaxgest.zeggs.inference import ZeggsModel_, load_model
from jaxgest.zeggs.steps import init_params

__all__ = ["count_params", "generate", "load_model", "ZeggsModel_"]

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


def generate(audio, styles: Union[StyleLike, Sequence[StyleLike]], *, workdir,
             weights: Optional[Sequence[float]] = None, seed: int = 0, temperature: float = 1.0,
             pca_edits: Optional[dict] = None, normalize_weights: bool = False,
             weight_format: str = "fp32") -> Motion:
    """Gestures for ``audio`` (a WAV/FLAC path, or ``(samples, sample_rate)``) in the style of ``styles``.

    ``styles``: one Motion or BVH path, or a list of them, blended as ``sum_i w_i e_i`` with ``weights``
    as given (one per clip, finite; default ``1 / n`` each; (2, 0) gives twice the first embedding);
    ``normalize_weights=True`` divides them by their sum (which must be positive). ``seed`` and ``temperature`` drive the style-embedding sample;
    ``pca_edits`` ``{component: delta in std}`` needs ``workdir/pca.json`` (``jaxgest zeggs pca``).
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
    return load_model(workdir).generate(audio, _as_motions(styles), weights=weights, seed=seed,
                                        temperature=temperature, pca_edits=pca_edits, sr=sr,
                                        normalize_weights=normalize_weights, weight_format=weight_format)


def count_params(preset: str | ZeggsConfig = "paper") -> dict[str, int]:
    """Parameters of a freshly initialised model: ``{"speech_encoder", "style_encoder", "generator"}``.

    Shapes only (``jax.eval_shape``): nothing is allocated. The paper preset assumes the paper's 75-joint
    rig, pose vector 15 * 75 + 6 = 1131 channels.
    """
    cfg = preset if isinstance(preset, ZeggsConfig) else get_config(preset)
    shapes = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.PRNGKey(0))
    return {name: int(sum(np.prod(x.shape) for x in jax.tree_util.tree_leaves(shapes[name])))
            for name in ("speech_encoder", "style_encoder", "generator")}

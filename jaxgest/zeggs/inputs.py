"""The inputs of ZeroEGGS generation, shared by jaxgest's models and the authors'
(``jaxgest.zeggs.official``): style clips, audio, blend weights and the padded sequence lengths that share a
compilation.

References: Ghorbani et al. 2023, §5.2.1 (blending and scaling of style embeddings).
"""

from __future__ import annotations

import os
import pathlib
from typing import Optional, Union

import numpy as np

from jaxgest.motion import bvh
from jaxgest.motion.skeleton import Motion
from jaxgest.runtime.errors import JaxgestError

StyleLike = Union[Motion, str, os.PathLike]


def as_motions(styles) -> list[Motion]:
    """One style clip or a list of them (Motions or BVH paths) -> a non-empty list of Motions."""
    if isinstance(styles, (Motion, str, os.PathLike)):
        styles = [styles]
    out = []
    for s in styles:
        if not isinstance(s, (Motion, str, os.PathLike)):
            raise JaxgestError(f"a style must be a Motion or a BVH path, got {type(s).__name__}")
        out.append(bvh.as_motion(s, "style"))
    if not out:
        raise JaxgestError("at least one style clip is needed")
    return out


def audio_input(audio, sr: Optional[int] = None):
    """``audio`` as ``(path, None)`` or ``(samples float32, sample_rate)``: a path (must exist), a
    ``(samples, sample_rate)`` pair, or samples with ``sr``."""
    if isinstance(audio, tuple):
        if len(audio) != 2:
            raise JaxgestError("audio must be a path or a (samples, sample_rate) pair")
        return np.asarray(audio[0], np.float32), int(audio[1])
    if isinstance(audio, (str, os.PathLike)):
        if not pathlib.Path(audio).is_file():
            raise JaxgestError(f"{audio}: no such audio file")
        return audio, None
    if isinstance(audio, np.ndarray) or hasattr(audio, "__array__"):
        if sr is None:
            raise JaxgestError("an audio array needs its sample rate: pass (samples, sample_rate)")
        return np.asarray(audio, np.float32), int(sr)
    raise JaxgestError("audio must be a path or a (samples, sample_rate) pair")


def validate_weights(weights, count: int, *, normalize: bool = False) -> np.ndarray:
    """Blend weights as an array: one per style clip, finite (default ``1 / count`` each).

    ``normalize=True``: divided by their sum, which must then be positive.
    References: Ghorbani et al. 2023, §5.2.1 (blending and scaling of style embeddings).
    """
    if weights is None:
        return np.full(count, 1.0 / count)
    w = np.asarray(list(weights), np.float64)
    if w.ndim != 1 or len(w) != count:
        raise JaxgestError(f"blend weights: got {w.size} weight(s) for {count} style clip(s)")
    if not np.all(np.isfinite(w)):
        raise JaxgestError(f"blend weights must be finite, got {w.tolist()}")
    if normalize:
        if w.sum() <= 0:
            raise JaxgestError(f"normalised blend weights must have a positive sum, got {w.tolist()}")
        w = w / w.sum()
    return w


def bucket_length(n: int, smallest: int = 64) -> int:
    """The smallest of 64, 96, 128, 192, 256, 384, ... (2^k and 1.5 * 2^k) that is >= ``n``: sequence
    lengths padded to these share a compilation (at most 1.5x the frames)."""
    L = smallest
    while L < n:
        L = L * 3 // 2 if (L & (L - 1)) == 0 else L * 4 // 3
    return L

"""PCA control of the ZeroEGGS style embedding space.

Fit a PCA on style embeddings (the posterior means of many style windows), then edit an embedding by
moving it along chosen principal components and projecting back: ``e' = e + sum_k delta_k * sigma_k * v_k``
where ``v_k`` is the k-th component (unit) and ``sigma_k`` its standard deviation, so ``delta`` is in
standard deviations of the data along that component. The authors' public code has no PCA control; the
paper shows it (§5.2.2, Fig. 8).

References: Ghorbani et al. 2023, §5.2.2 ("Control via PCA components").
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
from typing import Mapping

import numpy as np

from jaxgest.runtime.errors import CheckpointError, JaxgestError
from jaxgest.runtime.io import write_text_atomic


@dataclasses.dataclass(frozen=True)
class StylePCA:
    """mean (D,), components (K, D) orthonormal rows, std (K,), explained variance ratio (K,)."""

    mean: np.ndarray
    components: np.ndarray
    std: np.ndarray
    explained_variance_ratio: np.ndarray
    num_samples: int

    @property
    def num_components(self) -> int:
        return int(self.components.shape[0])

    def project(self, e: np.ndarray) -> np.ndarray:
        """Coordinates ``(..., K)`` of embeddings ``(..., D)`` in the PCA basis (not whitened)."""
        return (np.asarray(e, np.float64) - self.mean) @ self.components.T

    def edit(self, e: np.ndarray, edits: Mapping[int, float]) -> np.ndarray:
        """Move embeddings along components: ``{k: delta}`` with k 0-based and delta in std units."""
        e = np.array(e, np.float64, copy=True)
        for k, delta in edits.items():
            if not 0 <= int(k) < self.num_components:
                raise JaxgestError(
                    f"PCA component {k} does not exist (the fitted PCA has components 0..{self.num_components - 1})"
                )
            if not np.isfinite(delta):
                raise JaxgestError(f"PCA edit for component {k} is not finite: {delta}")
            e = e + float(delta) * self.std[int(k)] * self.components[int(k)]
        return e

    def save(self, path) -> None:
        write_text_atomic(path, json.dumps({
            "mean": self.mean.tolist(), "components": self.components.tolist(), "std": self.std.tolist(),
            "explained_variance_ratio": self.explained_variance_ratio.tolist(), "num_samples": self.num_samples,
        }) + "\n")

    @classmethod
    def load(cls, path) -> "StylePCA":
        path = pathlib.Path(path)
        if not path.is_file():
            raise CheckpointError(f"{path}: no PCA fitted yet (run `jaxgest zeggs pca --workdir W --data DIR`)")
        try:
            d = json.loads(path.read_text())
            return cls(np.asarray(d["mean"]), np.asarray(d["components"]), np.asarray(d["std"]),
                       np.asarray(d["explained_variance_ratio"]), int(d["num_samples"]))
        except (ValueError, KeyError) as e:
            raise CheckpointError(f"{path}: unreadable PCA file ({e})") from None


def fit_pca(embeddings: np.ndarray, num_components: int | None = None) -> StylePCA:
    """PCA of ``(N, D)`` embeddings by SVD of the centred data; components sorted by variance."""
    x = np.asarray(embeddings, np.float64)
    if x.ndim != 2 or x.shape[0] < 2:
        raise JaxgestError(f"PCA needs at least 2 embeddings, got shape {x.shape}")
    mean = x.mean(axis=0)
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    var = s ** 2 / (x.shape[0] - 1)
    k = min(num_components or len(s), len(s))
    total = var.sum()
    ratio = var / total if total > 0 else np.zeros_like(var)
    # Deterministic sign: the largest-magnitude coordinate of each component is positive.
    signs = np.sign(vt[np.arange(len(vt)), np.argmax(np.abs(vt), axis=1)])
    vt = vt * signs[:, None]
    return StylePCA(mean, vt[:k], np.sqrt(var[:k]), ratio[:k], int(x.shape[0]))


def parse_edits(specs) -> dict[int, float]:
    """``["0=2.0", "1=-1.5"]`` -> ``{0: 2.0, 1: -1.5}``; clear error for a malformed spec."""
    out = {}
    for spec in specs or ():
        try:
            k, v = spec.split("=", 1)
            out[int(k)] = float(v)
        except ValueError:
            raise JaxgestError(f"--pca-edit {spec!r}: expected COMPONENT=DELTA, e.g. 0=2.0") from None
    return out

"""Shared pieces of the metric tests (tests/test_metrics_*.py)."""

from __future__ import annotations

import numpy as np


def random_walk(rng: np.random.Generator, n: int, c: int = 3) -> np.ndarray:
    """``(n, c)`` cumulative sum of standard normal steps: a smooth-ish trajectory for DTW and error metrics."""
    return np.cumsum(rng.normal(size=(n, c)), axis=0)

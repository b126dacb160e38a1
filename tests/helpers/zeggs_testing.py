"""Shared pieces of the ZeroEGGS model tests: a small synthetic training batch of the tiny preset."""

from __future__ import annotations

import numpy as np

from jaxgest.zeggs.config import preset

P = preset("tiny").model.pose_dim


def zeggs_batch(B=2, T=8, S_=12, seed=0):
    """A tiny-preset batch: B rows of T frames (smooth normalised pose, random speech), style windows of S_
    frames (the first row full, the others masked to S_ - 4)."""
    rng = np.random.default_rng(seed)
    t = np.arange(T, dtype=np.float32)[None, :, None] / T
    phase = rng.uniform(0, 6, size=(B, 1, P)).astype(np.float32)
    pose = 0.5 * np.sin(2 * np.pi * t + phase)  # smooth normalised features
    q = np.zeros((B, T, 4), np.float32)
    q[..., 0] = 1.0
    lengths = np.array([S_] + [S_ - 4] * (B - 1))
    return {
        "speech": rng.normal(size=(B, T, 81)).astype(np.float32),
        "pose": pose.astype(np.float32),
        "root_position": np.zeros((B, T, 3), np.float32),
        "root_rotation": q,
        "style": rng.normal(size=(B, S_, P)).astype(np.float32),
        "style_mask": np.arange(S_)[None] < lengths[:, None],
        "facing": np.tile(np.array([0.0, 0.0, 1.0], np.float32), (B, 1)),
    }


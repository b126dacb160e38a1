"""Shared by this experiment's scripts: the peer case's TGST transfer and paired interleaved rounds."""
from __future__ import annotations

import os
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))

import jax  # noqa: E402
import numpy as np  # noqa: E402

from jaxgest.bench.cases import peers  # noqa: E402
from jaxgest.bench.cases import tgst as T  # noqa: E402
from jaxgest.tgst import model as M  # noqa: E402


def transfer_case(batch: int):
    """(params, content, style, f): the peer benchmark's network (authors' variant, random weights), content
    and style clips of 1280 frames, and the un-jitted soft transfer ``f(params, content, style) -> (upper, lower)``."""
    cfg = peers.TCFG

    def f(params, content, style):
        upper, lower, _ = M.transfer_arrays(params, content, style, cfg=cfg, method="soft")
        return upper, lower
    return (peers.tgst_params(),) + T._clips(batch, 1280) + (f,)


def max_diff(out, ref) -> float:
    return max(float(np.abs(np.asarray(a, np.float64) - np.asarray(r, np.float64)).max()) for a, r in zip(out, ref))


def interleaved(calls: dict, *, rounds: int = 11, inner: int = 5, reference: str | None = None) -> dict:
    """Time ``calls`` ({name: zero-argument callable}) in interleaved rounds (A B A B ...), ``inner`` calls each
    per round; print each one's wall median / min and CPU median (ms per call) and the paired ratio
    reference / name of wall and of process CPU time over rounds (mean +- SE). Returns the per-round times."""
    reference = reference or next(iter(calls))
    wall = {k: [] for k in calls}
    cpu = {k: [] for k in calls}
    for _ in range(rounds):
        for k, call in calls.items():
            t0, q0 = time.perf_counter(), time.process_time()
            for _ in range(inner):
                jax.block_until_ready(call())
            wall[k].append((time.perf_counter() - t0) / inner)
            cpu[k].append((time.process_time() - q0) / inner)
    for k in calls:
        rw = np.array(wall[reference]) / np.array(wall[k])
        rc = np.array(cpu[reference]) / np.array(cpu[k])
        se = lambda r: r.std(ddof=1) / np.sqrt(len(r))  # noqa: E731
        print(f"{k:<12} wall median {1e3 * np.median(wall[k]):.2f} ms, min {1e3 * min(wall[k]):.2f}, cpu "
              f"{1e3 * np.median(cpu[k]):.2f} | {reference}/{k}: wall {rw.mean():.2f} +- {se(rw):.2f}, "
              f"cpu {rc.mean():.2f} +- {se(rc):.2f}")
    print("load", os.getloadavg())
    return {"wall": wall, "cpu": cpu}

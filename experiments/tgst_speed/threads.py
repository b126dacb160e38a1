"""The batch split over two Python threads, each running the jitted transfer on half the batch (one device).

    python experiments/tgst_speed/threads.py [BATCH]

Paired interleaved rounds: ``jit`` (one call on the whole batch) against ``threads2`` (two threads, each a
call on one half, joined; the halves' outputs concatenated). JAX releases the GIL while a computation runs,
so the two calls can run on both cores at once. (Timing feasibility only: the authors' variant adds its
positional table along the batch axis, so the second half's outputs differ unless the offset is passed.)
"""
from __future__ import annotations

import sys
from concurrent.futures import ThreadPoolExecutor

import jax
import numpy as np

from common import interleaved, transfer_case

batch = int(sys.argv[1]) if len(sys.argv) > 1 else 8
params, content, style, f = transfer_case(batch)
fj = jax.jit(f)
h = batch // 2
c1, c2, s1, s2 = content[:h], content[h:], style[:h], style[h:]
pool = ThreadPoolExecutor(2)


def split():
    a = pool.submit(lambda: jax.block_until_ready(fj(params, c1, s1)))
    b = fj(params, c2, s2)
    jax.block_until_ready(b)
    a = a.result()
    return [np.concatenate([x, y]) for x, y in zip(a, b)]


jax.block_until_ready(fj(params, content, style)), split()
interleaved({"jit": lambda: fj(params, content, style), "threads2": split}, rounds=11, inner=5)

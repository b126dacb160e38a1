"""TGST transfer: fp32 against bf16 weights and inputs (outputs cast back to fp32), same process, interleaved.

    python bf16.py [BATCH]
"""
import sys

import jax
import jax.numpy as jnp
import numpy as np

from common import interleaved, transfer_case

params, content, style, f = transfer_case(int(sys.argv[1]) if len(sys.argv) > 1 else 8)
g = jax.jit(lambda p, c, s: tuple(a.astype(jnp.float32) for a in f(p, c, s)))
cast = lambda t: jax.tree.map(lambda x: x.astype(jnp.bfloat16) if x.dtype == jnp.float32 else x, t)  # noqa: E731
pb, cb, sb = cast(params), cast(content), cast(style)
ref, out = g(params, content, style), g(pb, cb, sb)
for a, r in zip(out, ref):
    a, r = np.asarray(a), np.asarray(r)
    print("max|diff| %.2e rms %.2e, reference range %.2e" % (np.abs(a - r).max(), np.sqrt(((a - r) ** 2).mean()),
                                                             np.ptp(r, axis=(0, 1)).mean()))
interleaved({"fp32": lambda: g(params, content, style), "bf16": lambda: g(pb, cb, sb)}, rounds=9, inner=3)

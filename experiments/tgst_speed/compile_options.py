"""TGST transfer: XLA compiler options per executable against the default (same process, interleaved rounds).

    python compile_options.py BATCH '{"name": {"xla_option": value, ...}, ...}'      (env R: rounds, default 11)
"""
import json
import os
import sys

import jax

from common import interleaved, max_diff, transfer_case

b, variants = int(sys.argv[1]), json.loads(sys.argv[2])
params, content, style, f = transfer_case(b)
lowered = jax.jit(f).lower(params, content, style)
fns = {"default": lowered.compile()}
for name, opts in variants.items():
    try:
        fns[name] = lowered.compile(compiler_options=opts)
    except Exception as e:  # an option this jaxlib does not know
        print(name, "failed:", str(e)[:200])
ref = fns["default"](params, content, style)
for k, fn in fns.items():
    print(k, "max|diff| %.2e" % max_diff(fn(params, content, style), ref))
interleaved({k: (lambda fn=fn: fn(params, content, style)) for k, fn in fns.items()},
            rounds=int(os.environ.get("R", 11)), inner=5 if b > 1 else 20)

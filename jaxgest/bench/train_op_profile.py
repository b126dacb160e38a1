"""Per-operation profile of the jitted TGST training steps (the ``peer_train_*`` cases' JAX side), no torch.

``python -m jaxgest.bench.train_op_profile [autoencoder|transformer ...]`` (env ``N`` profiled calls, default 3;
``TOP`` ops listed, default 15; ``PRESET``, default ``paper``; ``WINDOW``, the transformer's frames, default the
preset's): the preset's steps at their batch shapes (``paper``: autoencoder 32 x 256 frames; transformer 8 pairs of
1280 frames; ``PRESET=fit-motion WINDOW=288`` is what a fit-motion run on Bandai-Namco-1 trains), the authors'
transformer variant (the peers' network), random weights, under
``jax.profiler.trace`` (the method of :mod:`jaxgest.bench.tgst_profile`: each XLA operation's event time
summed over XLA's threads, so on a busy machine the times include preemption). Prints the total per call,
the time per kind of operation (conv or dot / YNNPACK fusion / elementwise or copy) and per direction
(forward / backward (``transpose``/``jvp`` in the source op name) / optimiser), and the largest operations.
"""

from __future__ import annotations

import collections
import os
import sys


from jaxgest.bench.tgst_profile import hlo_tables, op_times


def profile_compiled(compiled, args, *, calls: int = 3, top: int = 15, title: str = "") -> dict:
    meta, shape = hlo_tables(compiled.as_text())
    per_op, load0 = op_times(compiled, args, calls=calls)

    def kind(name):
        m, sh = meta.get(name, ""), shape.get(name, "")
        if "conv_general_dilated" in m or sh.endswith((" convolution", " dot")):
            return "conv or dot"
        return "YNNPACK fusion" if name.startswith("ynn") else "elementwise or copy"

    def direction(name):
        m = meta.get(name, "")
        if "transpose(" in m or "jvp(" in m:
            return "backward"
        if "adam" in m.lower() or "apply_gradients" in m or "update" in m.lower():
            return "optimiser"
        return "forward" if m else "unattributed"

    total = sum(per_op.values())
    kinds, dirs = collections.Counter(), collections.Counter()
    for name, ns in per_op.items():
        kinds[kind(name)] += ns
        dirs[direction(name)] += ns
    print(f"{title}: {total / 1e6:.2f} ms of operation time per call (summed over threads, {calls} calls); "
          f"load {load0} -> {os.getloadavg()}")
    for group in (kinds, dirs):
        for k, ns in group.most_common():
            print(f"  {ns / 1e6:8.2f} ms {100 * ns / total:5.1f} %  {k}")
    for name, ns in per_op.most_common(top):
        print(f"  {ns / 1e6:8.2f} ms  {name:32s} {shape.get(name, '')[:44]:44s} {meta.get(name, '')[-60:]}")
    return {"total_ns": total, "kinds": dict(kinds), "directions": dict(dirs)}


def main(stages=("autoencoder", "transformer"), calls: int = 3, top: int = 15, preset: str = "paper",
         window: int | None = None) -> dict:
    from jaxgest.bench.cases import peers_train as PT

    out = {}
    for stage in stages:
        case = (PT.ae_case(preset, with_torch=False) if stage == "autoencoder"
                else PT.transformer_case(preset, with_torch=False, window=window))
        args = case.make_args()
        compiled = case.impls[0].fn.lower(*args).compile()
        ops = sum(1 for line in compiled.as_text().splitlines() if " fusion(" in line or " dot(" in line
                  or " convolution(" in line or " custom-call(" in line)
        out[stage] = profile_compiled(compiled, args, calls=calls, top=top, title=f"TGST {preset} {stage} training "
                                      f"step (batch {case.batch} x {case.frames} frames, {ops} XLA operations)")
    return out


if __name__ == "__main__":
    main(tuple(sys.argv[1:]) or ("autoencoder", "transformer"), int(os.environ.get("N", "3")),
         int(os.environ.get("TOP", "15")), os.environ.get("PRESET", "paper"),
         int(os.environ["WINDOW"]) if os.environ.get("WINDOW") else None)

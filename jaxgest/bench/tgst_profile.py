"""Per-operation profile of the jitted TGST transfer (the peer case's network), no torch needed.

``python -m jaxgest.bench.tgst_profile [BATCH]`` (env ``N`` profiled calls, default 10; ``TOP`` ops listed,
default 25): the authors' variant (``jaxgest.bench.cases.peers.TCFG``), content 1280 + style 1280 frames,
random weights; runs ``N`` calls under ``jax.profiler.trace`` and sums each XLA operation's event time
over XLA's threads (so on a busy machine the times include preemption). Prints the total per call, the
time per part (autoencoder / transformer / swap, tokens, padding) and kind (conv or dot / YNNPACK fusion /
elementwise or copy), and the largest operations with their HLO shapes and source op names.
"""

from __future__ import annotations

import collections
import glob
import os
import re
import sys
import tempfile

import jax
from jax._src.lib import _profile_data

from jaxgest.bench.cases import peers
from jaxgest.bench.cases import tgst as T
from jaxgest.tgst import model as M


def hlo_tables(hlo: str) -> tuple[dict, dict]:
    """(op name -> source op_name, op name -> "shape opcode") of the entry computation."""
    meta, shape = {}, {}
    for line in hlo[hlo.index("ENTRY"):].splitlines():
        m = re.match(r"\s*(?:ROOT )?%?([\w.\-]+) = (\S+) (\w+)\(.*?(?:op_name=\"([^\"]+)\")?", line)
        if m:
            shape[m.group(1)] = f"{m.group(2)} {m.group(3)}"
        m2 = re.match(r"\s*(?:ROOT )?%?([\w.\-]+) = .*?op_name=\"([^\"]+)\"", line)
        if m2:
            meta[m2.group(1)] = re.sub(r"jit\([^)]*\)/", "", m2.group(2), count=1)
    return meta, shape


def op_times(compiled, args, *, calls: int, warmup: int = 2):
    """Mean time per call of every operation of ``compiled(*args)`` (ns, from one ``jax.profiler`` trace of
    ``calls`` calls after ``warmup`` untimed ones) and the load average before the trace."""
    for _ in range(warmup):
        jax.block_until_ready(compiled(*args))
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as d:
        with jax.profiler.trace(d):
            for _ in range(calls):
                jax.block_until_ready(compiled(*args))
        pd = _profile_data.ProfileData.from_file(glob.glob(f"{d}/**/*.xplane.pb", recursive=True)[0])
    per_op = collections.Counter()
    for plane in pd.planes:
        for line in plane.lines:
            if line.name == "python":
                continue
            for ev in line.events:
                if not ev.name.startswith(("ThunkExecutor", "end: ")):
                    per_op[ev.name] += ev.duration_ns / calls
    return per_op, load0


def main(batch: int = 8, calls: int = 10, top: int = 25) -> dict:
    cfg, params = peers.TCFG, peers.tgst_params()
    content, style = T._clips(batch, 1280)
    f = jax.jit(lambda p, c, s: M.transfer_arrays(p, c, s, cfg=cfg)[:2])
    compiled = f.lower(params, content, style).compile()
    meta, shape = hlo_tables(compiled.as_text())
    per_op, load0 = op_times(compiled, (params, content, style), calls=calls, warmup=3)

    def part(name):
        m = meta.get(name, name)
        if "StyleTransformer" in m:
            return "transformer"
        if "MotionAutoencoder" in m:
            return "autoencoder"
        return "swap / tokens / padding / trim"

    def kind(name):
        m, sh = meta.get(name, ""), shape.get(name, "")
        if "conv_general_dilated" in m or sh.endswith((" convolution", " dot")):
            return "conv or dot"
        return "YNNPACK fusion" if name.startswith("ynn") else "elementwise or copy"

    total = sum(per_op.values())
    groups = collections.Counter()
    for name, ns in per_op.items():
        groups[(part(name), kind(name))] += ns
    print(f"TGST transfer, batch {batch}, 1280 + 1280 frames: {total / 1e6:.2f} ms of operation time per "
          f"call (summed over threads, {calls} calls); load {load0} -> {os.getloadavg()}")
    for (p, k), ns in groups.most_common():
        print(f"  {ns / 1e6:7.3f} ms {100 * ns / total:5.1f} %  {p} | {k}")
    for name, ns in per_op.most_common(top):
        print(f"  {ns / 1e6:7.3f} ms  {name:32s} {shape.get(name, '')[:44]:44s} {meta.get(name, '')[-60:]}")
    return {"total_ns": total, "groups": dict(groups), "ops": dict(per_op)}


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 8, int(os.environ.get("N", 10)),
         int(os.environ.get("TOP", 25)))

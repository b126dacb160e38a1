"""Does timing jit right after torch slow the jit call? (torch's OpenMP workers spin after their region.)

    python experiments/tgst_speed/settle.py 8 [rounds]     # needs torch (pip install ".[bench]")

One process, the peer case's inputs and the same jitted TGST transfer. Interleaved rounds of six timed
blocks (each block ``inner`` calls, median of rounds):
  jit_alone       jit after jit (no torch call since the previous jit block)
  jit_after       jit right after a torch call (2 threads), as in the peer harness's rounds
  jit_settled     jit after a torch call and a 0.3 s pause
  jit_rewarmed    jit after a torch call and one untimed jit call
  torch           the torch peer (2 threads), right after a jit call
  torch_rewarmed  torch after a jit call and one untimed torch call
Prints each block's median wall ms and the ratios to jit_alone.
"""
from __future__ import annotations

import statistics
import sys
import time

import jax

from jaxgest.bench.cases.peers import tgst_case


def main(batch: int = 8, rounds: int = 15, inner: int = 5) -> dict:
    case = tgst_case(batch)
    args = case.make_args()
    jit_fn = case.impls[0].fn
    torch_fn = next(i.fn for i in case.impls if i.name == "torch")
    for _ in range(3):
        jax.block_until_ready(jit_fn(*args))
        torch_fn(*args)

    def block(fn):
        t = time.perf_counter()
        for _ in range(inner):
            jax.block_until_ready(fn(*args))
        return (time.perf_counter() - t) / inner * 1e3

    times = {"jit_alone": [], "jit_after": [], "jit_settled": [], "jit_rewarmed": [], "torch": [],
             "torch_rewarmed": []}
    for _ in range(rounds):
        block(jit_fn)
        times["jit_alone"].append(block(jit_fn))
        torch_fn(*args)
        times["jit_after"].append(block(jit_fn))
        torch_fn(*args)
        time.sleep(0.3)
        times["jit_settled"].append(block(jit_fn))
        torch_fn(*args)
        jax.block_until_ready(jit_fn(*args))
        times["jit_rewarmed"].append(block(jit_fn))
        times["torch"].append(block(torch_fn))
        jax.block_until_ready(jit_fn(*args))
        torch_fn(*args)
        times["torch_rewarmed"].append(block(torch_fn))
    med = {k: statistics.median(v) for k, v in times.items()}
    base = med["jit_alone"]
    print(f"batch {batch}, {rounds} rounds x {inner} calls")
    for k, v in med.items():
        print(f"  {k:12s} {v:8.2f} ms  ({v / base:.2f}x jit_alone)")
    print(f"  torch / jit_after {med['torch'] / med['jit_after']:.2f}x; "
          f"torch_rewarmed / jit_rewarmed {med['torch_rewarmed'] / med['jit_rewarmed']:.2f}x")
    return med


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 8, int(sys.argv[2]) if len(sys.argv) > 2 else 15)

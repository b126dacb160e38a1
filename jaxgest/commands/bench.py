"""``jaxgest bench``: the benchmark suite (:mod:`jaxgest.bench`), installed with the package."""

from __future__ import annotations

from jaxgest.bench import suite
from jaxgest.bench.options import add_arguments


def register(subparsers) -> None:
    p = subparsers.add_parser("bench", help="per-pose CPU cost benchmarks (JSON + markdown table)",
                              description="Per-pose CPU cost benchmarks (docs/design.md §8).")
    add_arguments(p)
    p.set_defaults(func=_run)


def _run(args) -> int:
    _, status = suite.run(args)
    return status

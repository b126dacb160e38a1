"""``jaxgest bench``: the benchmark suite, the same entry point as ``python -m benchmarks``.

``benchmarks/`` is a top-level folder of the repository, next to ``jaxgest/``, and is not installed by
pip. It is looked for in the clone this ``jaxgest`` was imported from (an editable install) and in the
current directory (a regular install run from a clone); otherwise the command fails with one line.
"""

from __future__ import annotations

import argparse
import importlib
import pathlib
import sys

from jaxgest.errors import JaxgestError


def _candidate_roots() -> list[pathlib.Path]:
    roots = [pathlib.Path(__file__).resolve().parents[2], pathlib.Path.cwd().resolve()]
    return [r for i, r in enumerate(roots) if r not in roots[:i] and (r / "benchmarks" / "harness.py").is_file()]


def find_benchmarks():
    """Import and return ``benchmarks.__main__`` from a jaxgest clone; :class:`JaxgestError` otherwise."""
    roots = _candidate_roots()
    loaded = sys.modules.get("benchmarks")
    if loaded is None:
        for root in reversed(roots):  # the first candidate ends up first on sys.path
            if str(root) not in sys.path:
                sys.path.insert(0, str(root))
    if not roots and loaded is None:
        raise JaxgestError("benchmarks/ not found: run `jaxgest bench` from the root of a jaxgest clone "
                           "(the suite is not installed by pip)")
    module = importlib.import_module("benchmarks")
    origin = pathlib.Path(getattr(module, "__file__", None) or "").resolve()
    if not (origin.parent / "harness.py").is_file():
        # Some unrelated installed distribution ships a top-level ``benchmarks`` package.
        raise JaxgestError(f"`import benchmarks` found {origin.parent}, not jaxgest's benchmark suite: "
                           "run `jaxgest bench` from the root of a jaxgest clone")
    return importlib.import_module("benchmarks.__main__")


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options shared by ``jaxgest bench`` and ``python -m benchmarks`` (here, so that ``jaxgest --help``
    works without the suite)."""
    parser.add_argument("--quick", action="store_true", help="fewer cases and repeats (< 2 minutes)")
    parser.add_argument("--json", metavar="OUT", help="write machine info and the records (SPEC §8) here")
    parser.add_argument("--plot", metavar="OUT.png", help="PNG of per-pose cost against clip length")
    parser.add_argument("--cases", metavar="PATTERN", default=None,
                        help="only these cases: comma-separated substrings or globs (e.g. 'peer_*,tgst_transfer')")
    parser.add_argument("--repeats", type=int, default=None, help="timed repeats per implementation")
    return parser


def register(subparsers) -> None:
    p = subparsers.add_parser("bench", help="per-pose CPU cost benchmarks (JSON + markdown table)",
                              description="Per-pose CPU cost benchmarks (SPEC §8); the same as "
                                          "`python -m benchmarks` from a clone.")
    add_arguments(p)
    p.set_defaults(func=_run)


def _run(args) -> int:
    _, status = find_benchmarks().run(args)
    return status

"""``jaxgest bench``: the benchmark suite (same as ``python -m benchmarks`` from a clone)."""

from __future__ import annotations

import importlib
import pathlib
import sys

from jaxgest.errors import JaxgestError


def _import_benchmarks():
    try:
        return importlib.import_module("benchmarks.__main__")
    except ModuleNotFoundError as e:
        if e.name not in ("benchmarks", "benchmarks.__main__"):
            raise
    # benchmarks/ lives beside jaxgest/ in a clone (it is not installed): try the clone and the cwd.
    for root in (pathlib.Path(__file__).resolve().parents[2], pathlib.Path.cwd()):
        if (root / "benchmarks" / "__main__.py").is_file():
            sys.path.insert(0, str(root))
            return importlib.import_module("benchmarks.__main__")
    raise JaxgestError("benchmarks/ not found: run `jaxgest bench` from a clone of the jaxgest repository")


def register(subparsers) -> None:
    p = subparsers.add_parser("bench", help="per-pose CPU cost benchmarks (JSON + markdown table)")
    p.add_argument("--quick", action="store_true", help="fewer cases and repeats (< 2 minutes)")
    p.add_argument("--json", metavar="OUT", help="write the records (SPEC §8) to this JSON file")
    p.add_argument("--plot", metavar="OUT.png", help="per-pose cost against clip length")
    p.add_argument("--cases", metavar="SUBSTRING", default=None, help="only cases whose name contains this")
    p.add_argument("--repeats", type=int, default=None, help="timed repeats per implementation")
    p.set_defaults(func=_run)


def _run(args) -> int:
    module = _import_benchmarks()
    if args.json:
        from jaxgest.io import check_output_path

        check_output_path(args.json)
    module.run(args)
    return 0

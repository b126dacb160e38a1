"""The options of ``jaxgest bench`` (also ``python -m jaxgest.bench``); light, so ``jaxgest --help`` stays fast."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.add_argument("--quick", action="store_true", help="fewer cases and repeats (< 2 minutes)")
    parser.add_argument("--json", metavar="OUT", help="write machine info and the records (docs/design.md §8) here")
    parser.add_argument("--plot", metavar="OUT.png", help="PNG of per-pose cost against clip length")
    parser.add_argument("--cases", metavar="PATTERN", default=None,
                        help="only these cases: comma-separated substrings or globs (e.g. 'peer_*,tgst_transfer')")
    parser.add_argument("--repeats", type=int, default=None, help="timed repeats per implementation")
    return parser

"""The ``jaxgest`` command line (SPEC §6). Thin: parse, then call the api modules.

Each command group lives beside its code and exposes ``register(subparsers)``; the registered parser
sets ``func`` to a callable ``func(args) -> int | None``. Every :class:`jaxgest.errors.JaxgestError`
becomes one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from jaxgest.errors import JaxgestError

# Modules that contribute subcommands, in help order. A module that fails to import is a bug, not a
# user error, so it is not hidden.
COMMAND_MODULES = (
    "jaxgest.commands.data",  # synth, render
    "jaxgest.tgst.cli",  # tgst ...
    "jaxgest.zeggs.cli",  # zeggs ...
    "jaxgest.commands.demo",  # demo, pipeline
    "jaxgest.commands.bench",  # bench
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxgest",
        description="Gesture animation in JAX: tokenized style transfer (TGST) and ZeroEGGS.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name == name:  # not written yet
                continue
            raise
        module.register(sub)
    return parser


class _ArgumentParserExit(Exception):
    pass


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        rc = args.func(args)
    except JaxgestError as e:
        print(f"jaxgest: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("jaxgest: interrupted", file=sys.stderr)
        return 130
    return int(rc or 0)


if __name__ == "__main__":
    sys.exit(main())

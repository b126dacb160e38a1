"""The ``jaxgest`` command line (docs/design.md §6). Thin: parse, then call the api modules.

Each command group lives in :mod:`jaxgest.commands` and exposes ``register(subparsers)``; the registered parser
sets ``func`` to a callable ``func(args) -> int | None``. Every :class:`jaxgest.runtime.errors.JaxgestError`, and
every ``OSError`` no module handled (a full or read-only disk, ...), becomes one line on stderr and exit
status 2; a training stopped by SIGINT / SIGTERM (:class:`jaxgest.runtime.errors.Interrupted`, raised once the
checkpoint of the interrupted step is saved) prints its one line and exits 130 / 143. Every command that reads
a workdir gets ``--strict`` (refuse an unreadable checkpoint instead of falling back to an older one).

The command owns its process, so it (and only it) installs the process-wide filter of asyncio's "Event loop
is closed" noise (:func:`jaxgest.runtime.orbax_noise.mute_closed_loop_errors_for_process`); library code scopes it.

Progress bars (tqdm, drawn on stderr) are shown only when stderr is a terminal: when it is a file or a
pipe, the bars' carriage-return redraws are dropped, so a failed command's stderr is exactly its one-line
``jaxgest: <message>`` (and a log holds no bar fragments). Other stderr output passes through unchanged.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys

from jaxgest.commands import bench, data, demo, plot, tgst, zeggs
from jaxgest.runtime.errors import Interrupted, JaxgestError

# Modules that contribute subcommands, in help order (each imports its heavy parts inside its commands).
COMMAND_MODULES = (
    data,  # synth, render
    tgst,  # tgst ...
    zeggs,  # zeggs ...
    demo,  # demo, pipeline
    plot,  # plot (training curves)
    bench,  # bench
)


WORKDIR_OPTIONS = ("--workdir", "--zeggs-workdir", "--tgst-workdir")


def _leaf_parsers(parser: argparse.ArgumentParser):
    """Every (sub)command parser that runs something (has no subcommands of its own)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield parser
    for action in subs:
        for child in dict.fromkeys(action.choices.values()):  # aliases map to the same parser
            yield from _leaf_parsers(child)


def add_strict_flag(parser: argparse.ArgumentParser) -> None:
    """``--strict`` on every command that reads a workdir's checkpoints: refuse an unreadable checkpoint
    instead of falling back to the newest readable one (:func:`jaxgest.runtime.checkpoint.strict_checkpoints`)."""
    for p in _leaf_parsers(parser):
        options = {o for a in p._actions for o in a.option_strings}
        if options & set(WORKDIR_OPTIONS) and "--strict" not in options:
            p.add_argument("--strict", action="store_true",
                           help="stop at an unreadable checkpoint instead of falling back to the newest "
                                "readable one")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxgest",
        description="Gesture animation in JAX: tokenized style transfer (TGST) and ZeroEGGS.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in COMMAND_MODULES:
        module.register(sub)
    add_strict_flag(parser)
    return parser


class _NoProgressBars(io.TextIOBase):
    """A text stream forwarding everything but tqdm's progress-bar writes to ``stream``.

    tqdm draws a bar as one write starting with ``"\r"`` and ends a kept bar with a lone ``"\n"``; both
    are dropped (the newline only right after a dropped bar).
    """

    def __init__(self, stream):
        super().__init__()
        self._stream = stream
        self._after_bar = False

    def write(self, text: str) -> int:
        if text.startswith("\r") or (self._after_bar and text == "\n"):
            self._after_bar = text.startswith("\r")
            return len(text)
        self._after_bar = False
        return self._stream.write(text)

    def flush(self) -> None:
        self._stream.flush()

    def isatty(self) -> bool:
        return False

    @property
    def encoding(self):
        return getattr(self._stream, "encoding", "utf-8")


def _stderr_without_bars():
    try:
        terminal = sys.stderr.isatty()
    except (AttributeError, ValueError):
        terminal = False
    return contextlib.nullcontext() if terminal else contextlib.redirect_stderr(_NoProgressBars(sys.stderr))


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from jaxgest.runtime.checkpoint import strict_checkpoints
    from jaxgest.runtime.orbax_noise import mute_closed_loop_errors_for_process

    # the command owns the process: asyncio "Event loop is closed" noise of a damaged checkpoint's reads can
    # still surface at interpreter exit, after every Checkpointer is closed
    mute_closed_loop_errors_for_process()
    strict = strict_checkpoints(True) if getattr(args, "strict", False) else contextlib.nullcontext()
    try:
        with _stderr_without_bars(), strict:
            rc = args.func(args)
    except Interrupted as e:  # a checkpoint of the interrupted step was saved
        print(f"jaxgest: {_one_line(str(e))}", file=sys.stderr)
        return e.status
    except JaxgestError as e:
        print(f"jaxgest: {_one_line(str(e))}", file=sys.stderr)
        return 2
    except OSError as e:  # the environment: a full or read-only disk, a vanished folder, ...
        print(f"jaxgest: {_one_line(os_error_message(e))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("jaxgest: interrupted", file=sys.stderr)
        return 130
    return int(rc or 0)


def os_error_message(e: OSError) -> str:
    """``<file>: <reason>`` of an operating-system error no jaxgest module turned into its own message."""
    why = e.strerror or str(e) or type(e).__name__
    name = e.filename if e.filename is not None else None
    if name is None:
        return why
    other = f" -> {e.filename2}" if getattr(e, "filename2", None) else ""
    return f"{name}{other}: {why}"


def _one_line(text: str) -> str:
    return " ".join(text.split()) if "\n" in text or "\r" in text else text


if __name__ == "__main__":
    sys.exit(main())

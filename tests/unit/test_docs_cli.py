"""docs/cli.md (and the README's command list) against the argparse parser (issue 59, part 4).

The parser is the one the command line runs (:func:`jaxgest.cli.build_parser`). Checked: every command that
runs something has its ``## <command>`` section in docs/cli.md, and that section names each of its flags and
each ``choices`` value of its arguments; every flag the doc names exists (in the command of the usage line it
is written in, and anywhere else in some command); a ``--flag a|b|c`` alternation in docs/cli.md or the
README lists exactly the flag's choices. A flag added to the parser fails here until it is documented.
"""

from __future__ import annotations

import argparse
import pathlib
import re

import pytest

from jaxgest.cli import build_parser

ROOT = pathlib.Path(__file__).resolve().parents[2]
CLI_DOC = ROOT / "docs" / "cli.md"
README = ROOT / "README.md"
HELP = {"-h", "--help"}  # every command's, documented once in the doc's first line

_FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*(?![\w-])")
_COMMENT = re.compile(r"(?<=\S)\s{2,}(?=[\w(#])")
_ALTERNATION = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)[ =]([\w.-]+(?:\|[\w.-]+)+)")


def commands(parser: argparse.ArgumentParser, path=()) -> dict[str, argparse.ArgumentParser]:
    """``"tgst train" -> parser`` for every command that runs something (aliases once)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return {" ".join(path): parser}
    out = {}
    for action in subs:
        for name, child in action.choices.items():
            if child not in out.values():
                out.update(commands(child, path + (name,)))
    return out


def flags(parser: argparse.ArgumentParser) -> set[str]:
    return {o for a in parser._actions for o in a.option_strings} - HELP


def choices(parser: argparse.ArgumentParser) -> dict[str, list[str]]:
    """flag (or positional name) -> its choices."""
    return {(a.option_strings[-1] if a.option_strings else a.dest): [str(c) for c in a.choices]
            for a in parser._actions if a.choices and not isinstance(a, argparse._SubParsersAction)}


def sections(doc: str) -> dict[str, str]:
    """``## heading`` -> its text (up to the next ``## ``); the text before the first heading under ""."""
    out, name = {"": []}, ""
    for line in doc.splitlines():
        if line.startswith("## "):
            name = line[3:].strip()
            out[name] = []
        else:
            out[name].append(line)
    return {k: "\n".join(v) for k, v in out.items()}


def usage_lines(doc: str) -> list[str]:
    """Every ``jaxgest ...`` usage: a code-block line starting with it, with its indented continuation lines,
    or an inline code span starting with it. A code-block line ends where a comment column starts after its
    first flag (two or more spaces, then a word or ``#``)."""
    out, block, current = [], False, None
    for line in doc.splitlines():
        if line.startswith("```"):
            block = not block
            current = None
            continue
        if block:
            if "--" in line:
                head, _, tail = line.partition("--")
                line = head + "--" + _COMMENT.split(tail, 1)[0]
            if line.startswith("jaxgest "):
                current = [line]
                out.append(current)
            elif current is not None and line.startswith(" "):
                current.append(line)
            else:
                current = None
        else:
            out += [[span] for span in re.findall(r"`(jaxgest [^`]+)`", line)]
    return [" ".join(u) for u in out]


def command_of(usage: str, known: dict) -> str | None:
    """The command a usage line runs (the longest run of its words naming one), None for a command group."""
    words = usage.split()[1:]
    for n in range(len(words), 0, -1):
        name = " ".join(words[:n])
        if name in known:
            return name
    return None


@pytest.fixture(scope="module")
def parsers():
    return commands(build_parser())


def _has_flag(text: str, flag: str) -> bool:
    return re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", text) is not None


def _has_word(text: str, word: str) -> bool:
    return re.search(rf"(?<![\w-]){re.escape(word)}(?![\w-])", text) is not None


def undocumented(doc: str, parsers: dict) -> list[str]:
    """What the parser has and the command's ``## <command>`` section does not name."""
    secs, out = sections(doc), []
    for name, parser in parsers.items():
        if name not in secs:
            out.append(f"command `jaxgest {name}`: no '## {name}' section")
            continue
        out += [f"{name}: flag {f}" for f in sorted(flags(parser)) if not _has_flag(secs[name], f)]
        out += [f"{name}: {flag} value {c!r}" for flag, cs in choices(parser).items() for c in cs
                if not _has_word(secs[name], c)]
    return out


def unknown_flags(doc: str, parsers: dict, anywhere: bool = True) -> list[str]:
    """Flags the doc names that no command has (``anywhere``: in all its text, else in its usage lines), or
    that a usage line gives a command without them."""
    every = set().union(HELP, *(flags(p) for p in parsers.values()))
    named = _FLAG.findall(doc if anywhere else "\n".join(usage_lines(doc)))
    out = [f"{f}: no command has it" for f in sorted(set(named) - every)]
    for usage in usage_lines(doc):
        name = command_of(usage, parsers)
        if name is not None:
            out += [f"`jaxgest {name}` has no {f} ({usage[:60]}...)" for f in _FLAG.findall(usage)
                    if f not in flags(parsers[name]) | HELP]
    return out


def wrong_alternations(doc: str, parsers: dict) -> list[str]:
    """``--flag a|b|c`` in a usage line whose values are not exactly the flag's choices."""
    out = []
    for usage in usage_lines(doc):
        name = command_of(usage, parsers)
        if name is None:
            continue
        for flag, values in _ALTERNATION.findall(usage):
            want = choices(parsers[name]).get(flag)
            if want is not None and sorted(values.split("|")) != sorted(want):
                out.append(f"jaxgest {name} {flag} {values}: the choices are {'|'.join(want)}")
    return out


def test_every_command_flag_and_choice_is_documented(parsers):
    missing = undocumented(CLI_DOC.read_text(), parsers)
    assert not missing, "not in docs/cli.md:\n  " + "\n  ".join(missing)


def test_every_documented_flag_exists(parsers):
    assert not unknown_flags(CLI_DOC.read_text(), parsers)
    assert not unknown_flags(README.read_text(), parsers, anywhere=False)  # it names pip's and pytest's too


def test_alternations_list_every_choice(parsers):
    for doc in (CLI_DOC, README):
        wrong = wrong_alternations(doc.read_text(), parsers)
        assert not wrong, f"{doc.name}:\n  " + "\n  ".join(wrong)


def test_the_checks_can_fail(parsers):
    """Controls: the doc is read whole, and altered copies of it (or of the parser) fail each check."""
    doc = CLI_DOC.read_text()
    assert set(parsers) <= set(sections(doc)) and len(parsers) >= 10
    assert len(usage_lines(doc)) >= 10 and any("zeggs evaluate" in u for u in usage_lines(doc))

    # a flag of the parser the doc does not name (as when a new flag is added): reported
    parser = build_parser()
    tgst_train = commands(parser)["tgst train"]
    tgst_train.add_argument("--new-flag")
    tgst_train.add_argument("--mode", choices=("tiny", "zzz-unlisted"))
    assert set(undocumented(doc, commands(parser))) - set(undocumented(doc, parsers)) == {
        "tgst train: flag --mode", "tgst train: flag --new-flag", "tgst train: --mode value 'zzz-unlisted'"}

    # a flag removed from its section (a prefix of another flag does not count as it): reported
    section = sections(doc)["zeggs evaluate"]
    assert _has_flag(section, "--heldout-seeds")
    cut = doc.replace(section, section.replace("--heldout ", "--heldout-seeds ").replace("--heldout`", "`"))
    assert set(undocumented(cut, parsers)) - set(undocumented(doc, parsers)) == {
        "zeggs evaluate: flag --heldout"}

    # a choice value left out of the section: reported
    section = sections(doc)["tgst transfer"]
    cut = doc.replace(section, section.replace("coherent", "c0herent"))
    assert set(undocumented(cut, parsers)) - set(undocumented(doc, parsers)) == {
        "tgst transfer: --method value 'coherent'"}

    # a flag no command has, and a real flag on the wrong command's usage line: reported
    bad = doc + "\n`jaxgest demo --quick --no-such-flag --workdir W`\n"
    assert unknown_flags(bad, parsers) == [
        "--no-such-flag: no command has it",
        "`jaxgest demo` has no --no-such-flag (jaxgest demo --quick --no-such-flag --workdir W...)",
        "`jaxgest demo` has no --workdir (jaxgest demo --quick --no-such-flag --workdir W...)"]

    # an alternation missing a choice (the README's old --method list): reported
    old = "```\njaxgest tgst transfer --workdir W --out O.bvh [--method soft|hard|adain|avatarnet]\n```\n"
    assert wrong_alternations(old, parsers) == [
        "jaxgest tgst transfer --method soft|hard|adain|avatarnet: "
        "the choices are soft|hard|adain|avatarnet|coherent|autoencoder"]

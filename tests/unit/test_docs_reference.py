"""docs/troubleshooting.md against the messages the code raises (issue 59, part 4).

The messages are read from the source with ``ast`` (tests/helpers/message_catalog.py): every ``raise`` of a
user-facing error (:class:`jaxgest.runtime.errors.JaxgestError` and its subclasses, the experiment driver's
``DriverError``), every error factory's message as called, every ``jaxgest: warning:`` line and the command
line's own stderr lines. Each is a pattern, its f-string placeholders wildcards. The doc's section "Every
message, by kind" lists them, one bullet per message with its placeholders written ``{...}``, under a
``### <Class>`` heading. Both directions are checked: every message is listed under its class (or a base
class), and every listed message is still raised; the example tables' messages must exist too.
"""

from __future__ import annotations

import pathlib

import message_catalog as mc

DOC = pathlib.Path(__file__).resolve().parents[2] / "docs" / "troubleshooting.md"


def _doc() -> str:
    return DOC.read_text()


def test_every_raised_message_is_listed_under_its_kind():
    missing, _ = mc.compare(_doc(), mc.messages())
    assert not missing, f"{len(missing)} message(s) raised, not in {DOC.name} ({mc.CATALOG}):\n" + "\n".join(
        f"  ### {p.cls}: - `{p.shown}`  ({p.where})" for p in sorted(missing, key=lambda p: (p.cls, p.shown)))


def test_every_listed_message_is_still_raised():
    _, stale = mc.compare(_doc(), mc.messages())
    assert not stale, f"{len(stale)} listed message(s) of {DOC.name} no longer raised:\n" + "\n".join(
        f"  line {e.line} (### {e.section}): {e.text}" for e in stale)


def test_every_example_message_exists():
    patterns = mc.collect()
    examples = mc.table_entries(_doc(), mc.CATALOG)
    assert len(examples) > 50  # the tables were read
    unknown = [e for e in examples if not any(p.matches(e.text) for p in patterns)]
    assert not unknown, "example messages no code raises:\n" + "\n".join(
        f"  line {e.line}: {e.text}" for e in unknown)


def test_the_catalog_is_read_whole():
    """Controls: the collector finds messages of every kind (factories and warnings included), and the doc
    parser reads every bullet, so the two checks above are not vacuous."""
    found = mc.messages()
    assert len(found) > 300
    kinds = {p.cls for p in found.values()}
    assert {"BVHError", "AudioError", "DataError", "CheckpointError", "WriteError", "TrainingError",
            "Interrupted", "WorkdirBusy", "JaxgestError", "DriverError", mc.WARNINGS, mc.CLI} <= kinds
    shown = {p.shown for p in found.values()}
    assert "{loc}: motion row contains NaN or inf" in shown  # through the BVH reader's error factory
    assert "{loc}: unknown channel {c} on joint {joint}" in shown  # a reason a helper returns, then raised
    assert "interrupted" in shown  # the command line's own line
    doc = _doc()
    bullets = sum(1 for line in doc.split(f"## {mc.CATALOG}", 1)[1].splitlines() if line.startswith("- `"))
    assert len(mc.catalog_entries(doc, mc.CATALOG)) == bullets


def test_a_missing_or_reworded_message_fails():
    """Negative controls on altered copies of the doc and of the code."""
    doc, found = _doc(), mc.messages()
    code = "{loc}: motion row contains NaN or inf"  # the BVH reader's message, as the code writes it
    entries = mc.catalog_entries(doc, mc.CATALOG)
    victim = next(e for e in entries if e.text == "{file}:{line}: motion row contains NaN or inf")
    lines = doc.splitlines()

    # the doc without that entry: its message is reported missing, nothing else changes
    without = "\n".join(lines[: victim.line - 1] + lines[victim.line:])
    missing, stale = mc.compare(without, found)
    assert [p.shown for p in missing] == [code] and stale == []

    # one word of the entry changed: reported stale, and its message missing
    reworded = doc.replace(f"`{victim.text}`", "`{file}:{line}: motion row contains NaN or infinity`")
    missing, stale = mc.compare(reworded, found)
    assert [p.shown for p in missing] == [code]
    assert [e.text for e in stale] == ["{file}:{line}: motion row contains NaN or infinity"]

    # a placeholder written where the code has words: not the message
    vague = doc.replace(f"`{victim.text}`", "`{file}:{line}: motion row contains {what}`")
    missing, stale = mc.compare(vague, found)
    assert [p.shown for p in missing] == [code]
    assert [e.text for e in stale] == ["{file}:{line}: motion row contains {what}"]

    # the entry listed under another kind: a BVHError is not listed by a CheckpointError bullet
    heading = next(i for i, line in enumerate(lines) if line.startswith("### CheckpointError"))
    moved = lines[: heading + 1] + ["", f"- `{victim.text}`"] + lines[heading + 1:]
    original = lines[victim.line - 1]
    moved = "\n".join(line for i, line in enumerate(moved) if not (i < heading and line == original))
    missing, stale = mc.compare(moved, found)
    assert [p.shown for p in missing] == [code] and [e.text for e in stale] == [victim.text]

    # the message reworded in the source: the old entry is stale, the new message missing
    renamed = dict(found)
    old = renamed.pop(("BVHError", code))
    new = mc.Pattern((old.parts[0], ": motion row holds NaN or inf"), old.cls, old.where)
    renamed[(new.cls, new.shown)] = new
    missing, stale = mc.compare(doc, renamed)
    assert [p.shown for p in missing] == [new.shown] and [e.text for e in stale] == [victim.text]


def test_collector_reads_a_new_raise(tmp_path):
    """A message added to the source is collected (an f-string's placeholders as wildcards, a factory's
    message with the call's argument in it), so a raise added without a doc entry fails the first test."""
    src = tmp_path / "pkg"
    src.mkdir()
    (src / "mod.py").write_text(
        "class JaxgestError(Exception): pass\n"
        "class NewError(JaxgestError): pass\n"
        "def error(line, reason):\n"
        "    return NewError(f'{line}: {reason}')\n"
        "def f(path, n):\n"
        "    if n:\n"
        "        raise NewError(f'{path}: {n} widgets is too many')\n"
        "    raise error(3, f'bad widget {n!r}')\n")
    found = mc.messages((src,))
    assert set(found) == {("NewError", "{path}: {n} widgets is too many"),
                          ("NewError", "{line}: bad widget {n}")}
    doc = _doc()
    missing, _ = mc.compare(doc, {**mc.messages(), **found})
    assert sorted(p.shown for p in missing) == ["{line}: bad widget {n}", "{path}: {n} widgets is too many"]


def test_matcher_wildcards():
    """A code wildcard matches any text (a doc placeholder or an example value); a doc placeholder never
    stands for the code's literal words."""
    p = mc.Pattern(("cannot parse ", mc.Wild("what"), " as a number"), "BVHError", "x.py:1")
    assert p.matches("cannot parse {what} as a number")
    assert p.matches("cannot parse motion value 'abc' as a number")
    assert not p.matches("cannot parse {what}")
    assert not p.matches("{reason} as a number")
    assert not p.matches("x cannot parse {what} as a number")

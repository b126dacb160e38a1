"""The user-facing messages the source raises, read with ``ast`` (nothing is imported), and a matcher of those
messages against the entries of ``docs/troubleshooting.md`` (tests/unit/test_docs_reference.py).

A message is collected where the code raises one of the project's errors (:class:`JaxgestError` and every
class deriving from it, found in the source; ``experiments``' :class:`DriverError`), or a call of an *error
factory* (a function that returns such an error built from its arguments, e.g. ``bvh._Lines.error`` or
``runtime.io.write_error``): the factory's message with the call's arguments put in for its parameters. Also
collected: ``warn(...)`` lines (``jaxgest: warning: ...``) and the command line's own stderr lines.

A message is a :class:`Pattern`: its literal text with a wildcard for each value filled in at run time (an
f-string's placeholders, a conditional part, a variable). ``Pattern.shown`` writes it as the doc does, each
wildcard as ``{expression}``; ``Pattern.matches(entry)`` says whether a doc entry is this message: the entry
with every wildcard matched by any text (the doc's own ``{...}`` placeholders included) and every literal
character of the message in place. A doc entry's placeholder never stands for literal text of the message, so
an entry whose wording no longer exists in the code does not match.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import pathlib
import re
from typing import Iterable, Optional

ROOT = pathlib.Path(__file__).resolve().parents[2]
#: source trees scanned for messages: the package and the experiment driver (``python -m experiments``)
SOURCES = (ROOT / "jaxgest", ROOT / "experiments")
#: the roots of the user-facing error classes (every subclass found in SOURCES counts too)
ROOT_ERRORS = ("JaxgestError", "DriverError")
#: functions whose string argument is printed as a ``jaxgest: warning: <message>`` line
WARNING_FUNCTIONS = ("warn",)
#: the doc section of the warning lines; the class of a message re-raised as ``type(e)(...)`` (any section)
WARNINGS, ANY_CLASS = "Warnings", "*"
#: the command line's own stderr lines (``jaxgest: <message>``), listed under the doc's ``### CLI`` heading
CLI_FILE, CLI_PREFIX, CLI = pathlib.Path("jaxgest/cli.py"), "jaxgest: ", "CLI"
#: a message with fewer literal letters than this wraps another message (``{name}: {e}``): not one of its own
MIN_LETTERS = 3


class Wild:
    """A value filled in at run time; ``text`` is how the doc writes it (the source expression)."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self):
        return f"Wild({self.text!r})"


@dataclasses.dataclass(frozen=True)
class Pattern:
    parts: tuple  # str and Wild, adjacent strings merged, adjacent wildcards merged
    cls: str  # the error class raised (WARNINGS for a warning line, ANY_CLASS for ``type(e)(...)``)
    where: str  # file:line of the raise

    @property
    def shown(self) -> str:
        return "".join(p if isinstance(p, str) else "{" + p.text + "}" for p in self.parts)

    @property
    def literal_letters(self) -> int:
        return sum(c.isalpha() for p in self.parts if isinstance(p, str) for c in p)

    def matches(self, entry: str) -> bool:
        """Whether ``entry`` is this message: its literal parts in order, each wildcard any text (a glob
        match: taking each literal at its leftmost place is enough)."""
        parts, pos, end = self.parts, 0, len(entry)
        if isinstance(parts[0], str):
            if not entry.startswith(parts[0]):
                return False
            pos, parts = len(parts[0]), parts[1:]
        if parts and isinstance(parts[-1], str):
            if not entry.endswith(parts[-1]) or end - len(parts[-1]) < pos:
                return False
            end, parts = end - len(parts[-1]), parts[:-1]
        elif not parts:
            return pos == end
        for p in parts:
            if isinstance(p, str):
                i = entry.find(p, pos, end)
                if i < 0:
                    return False
                pos = i + len(p)
        return True


def _normalise(parts: Iterable) -> tuple:
    out = []
    for p in parts:
        if isinstance(p, str):
            if not p:
                continue
            if out and isinstance(out[-1], str):
                out[-1] += p
                continue
        elif out and isinstance(out[-1], Wild):
            out[-1] = Wild(out[-1].text + "}{" + p.text)
            continue
        out.append(p)
    return tuple(out)


def _expr_text(node: ast.expr) -> str:
    return ast.unparse(node)


def string_parts(node: ast.expr, params: dict[str, tuple] | None = None) -> Optional[tuple]:
    """``node`` as message parts, or None when it is no string expression (a forwarded ``str(e)``, a
    variable). ``params`` maps a factory's parameter names to the parts of the call's arguments: a placeholder
    that is just such a name is replaced by them.
    """
    params = params or {}
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return (node.value,)
    if isinstance(node, ast.JoinedStr):
        parts = []
        for v in node.values:
            if isinstance(v, ast.Constant):
                parts.append(v.value)
            elif isinstance(v.value, ast.Name) and v.value.id in params:
                parts.extend(params[v.value.id])
            else:
                inner = string_parts(v.value, params) if isinstance(v.value, (ast.IfExp,)) else None
                parts.extend(inner if inner else (Wild(_expr_text(v.value)),))
        return _normalise(parts)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        left, right = string_parts(node.left, params), string_parts(node.right, params)
        if left is None and right is None:
            return None
        left = left or (Wild(_expr_text(node.left)),)
        return _normalise(left + (right or (Wild(_expr_text(node.right)),)))
    if isinstance(node, ast.IfExp):  # either branch: one wildcard (the doc names the condition in words)
        return (Wild(_expr_text(node)),)
    if isinstance(node, ast.Name) and node.id in params:
        return params[node.id]
    return None


def _callee(node: ast.expr) -> str:
    """The last name of a call's function: ``lines.error`` -> ``error``, ``type(e)`` -> ``type``."""
    f = node.func if isinstance(node, ast.Call) else node
    if isinstance(f, ast.Attribute):
        return f.attr
    if isinstance(f, ast.Name):
        return f.id
    if isinstance(f, ast.Call):
        return _callee(f)
    return ""


@functools.lru_cache(maxsize=None)
def _trees(sources: tuple = SOURCES) -> tuple:
    out = []
    for src in sources:
        for path in sorted(src.rglob("*.py")):
            out.append((path, ast.parse(path.read_text(), str(path))))
    return tuple(out)


def error_classes(trees) -> set[str]:
    """The user-facing error classes: the roots and every class deriving from one of them (a fixed point)."""
    classes = set(ROOT_ERRORS)
    defs = [n for _, t in trees for n in ast.walk(t) if isinstance(n, ast.ClassDef)]
    while True:
        new = {d.name for d in defs if d.name not in classes
               and any(ast.unparse(b).split(".")[-1] in classes for b in d.bases)}
        if not new:
            return classes
        classes |= new


@dataclasses.dataclass(frozen=True)
class Factory:
    params: tuple  # parameter names, ``self`` excluded
    message: ast.expr
    cls: str


def error_factories(trees, classes: set[str]) -> dict[str, Factory]:
    """Functions that return a user-facing error: ``return SomeError(<message>)``."""
    out = {}
    for _, tree in trees:
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if (isinstance(node, ast.Return) and isinstance(node.value, ast.Call)
                        and _callee(node.value) in classes and node.value.args):
                    args = fn.args.posonlyargs + fn.args.args
                    names = [a.arg for a in args if a.arg not in ("self", "cls")]
                    out[fn.name] = Factory(tuple(names), node.value.args[0], _callee(node.value))
    return out


def string_functions(trees) -> dict[str, list]:
    """Functions that return a message for a caller to raise (``reason = _channels_problem(...)``):
    name -> the string expressions they return."""
    out: dict[str, list] = {}
    for _, tree in trees:
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                returns = [n.value for n in ast.walk(fn) if isinstance(n, ast.Return) and n.value is not None
                           and isinstance(n.value, (ast.JoinedStr, ast.Constant)) and string_parts(n.value)]
                if returns:
                    out.setdefault(fn.name, []).extend(returns)
    return out


def _assignments(fn) -> dict[str, list]:
    """name -> the expressions assigned to it in a function (a message built before it is raised)."""
    out: dict[str, list] = {}
    for node in ast.walk(fn):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            out.setdefault(node.targets[0].id, []).append(node.value)
    return out


def alternatives(node: ast.expr, assigns: dict, strings: dict, params=None) -> list[tuple]:
    """The message parts ``node`` can be: a string expression; a variable assigned one (or the result of a
    function returning messages) in the same function; [] for a forwarded message (``str(e)``)."""
    parts = string_parts(node, params)
    if parts is not None:
        return [parts]
    if isinstance(node, ast.Name):
        return [a for v in assigns.get(node.id, []) if not isinstance(v, ast.Name)
                for a in alternatives(v, assigns, strings, params)]
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in strings:
        return [string_parts(v) for v in strings[node.func.id]]
    return []


def _factory_alternatives(factory: Factory, call: ast.Call, assigns: dict, strings: dict) -> list[tuple]:
    bound = dict(zip(factory.params, call.args))
    bound.update({kw.arg: kw.value for kw in call.keywords if kw.arg in factory.params})
    choices = {name: alternatives(arg, assigns, strings) or [(Wild(name),)] for name, arg in bound.items()}
    out = [{}]
    for name, alts in choices.items():
        out = [dict(d, **{name: a}) for d in out for a in alts]
    return [string_parts(factory.message, params) or (Wild(_expr_text(factory.message)),) for params in out]


def _raise_sites(tree):
    """(node, innermost enclosing function or the module) for every node, each visited once."""
    stack = [(tree, tree)]
    while stack:
        node, scope = stack.pop()
        yield node, scope
        inner = node if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) else scope
        stack.extend((child, inner) for child in ast.iter_child_nodes(node))


def collect(sources: tuple = SOURCES) -> tuple[Pattern, ...]:
    """Every user-facing message raised (or warned) in ``sources``, one Pattern per raise site and string."""
    return _collect(tuple(sources))


@functools.lru_cache(maxsize=None)
def _collect(sources: tuple) -> tuple[Pattern, ...]:
    trees = _trees(tuple(sources))
    classes = error_classes(trees)
    factories = error_factories(trees, classes)
    strings = string_functions(trees)
    found = []
    for path, tree in trees:
        rel = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        scope_assigns = {}
        for node, scope in _raise_sites(tree):
            call, cls = None, None
            if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
                call, name = node.exc, _callee(node.exc)
                if name == "type" or name in classes:  # ``raise type(e)(...)``: the class of a caught error
                    cls = ANY_CLASS if name == "type" else name
            elif isinstance(node, ast.Expr) and isinstance(node.value, ast.Call):
                call, name = node.value, _callee(node.value)
                if isinstance(call.func, ast.Name) and name in WARNING_FUNCTIONS:
                    cls = WARNINGS
                elif rel == CLI_FILE and name == "print" and any(
                        k.arg == "file" and ast.unparse(k.value) == "sys.stderr" for k in call.keywords):
                    cls = CLI  # the command line's own lines: "jaxgest: <message>"
            if call is None or (cls is None and not (isinstance(node, ast.Raise) and name in factories)):
                continue
            if id(scope) not in scope_assigns:
                scope_assigns[id(scope)] = _assignments(scope)
            assigns = scope_assigns[id(scope)]
            if cls is None:  # ``raise factory(...)``: the factory's message with the call's arguments in it
                f = factories[name]
                found += [Pattern(parts, f.cls, f"{rel}:{node.lineno}")
                          for parts in _factory_alternatives(f, call, assigns, strings)]
                continue
            if not call.args:
                continue
            for parts in alternatives(call.args[0], assigns, strings):
                if cls == CLI and isinstance(parts[0], str) and parts[0].startswith(CLI_PREFIX):
                    parts = _normalise((parts[0][len(CLI_PREFIX):],) + parts[1:])
                found.append(Pattern(parts, cls, f"{rel}:{node.lineno}"))
    return tuple(sorted(found, key=lambda p: p.where))


def messages(sources: tuple = SOURCES) -> dict[tuple, Pattern]:
    """The distinct documentable messages by (class, shown form); wrappers of another message left out."""
    out = {}
    for p in collect(sources):
        if p.literal_letters >= MIN_LETTERS:
            out.setdefault((p.cls, p.shown), p)
    return out


# --- the doc ----------------------------------------------------------------------------------------------

_BULLET = re.compile(r"^- (?:`` (?P<m2>.+?) ``|`(?P<m>[^`]+)`)(?P<rest>.*)$")
_HEADING = re.compile(r"^### (?P<cls>\w+)")
_SPAN = re.compile(r"``\s?(.+?)\s?``|`([^`]+)`")


@dataclasses.dataclass(frozen=True)
class Entry:
    text: str
    section: str  # the ``### Class`` heading it is listed under ("" for the example tables)
    line: int


def catalog_entries(doc: str, heading: str) -> list[Entry]:
    """The ``- `message` `` bullets of the doc's section ``## heading``, with their ``### Class`` heading."""
    out, inside, section = [], False, ""
    for i, line in enumerate(doc.splitlines(), 1):
        if line.startswith("## "):
            inside = line[3:].strip() == heading
            continue
        if not inside:
            continue
        if m := _HEADING.match(line):
            section = m["cls"]
        elif m := _BULLET.match(line):
            out.append(Entry(m["m"] or m["m2"], section, i))
    return out


def table_entries(doc: str, heading: str) -> list[Entry]:
    """The messages in the first column of the doc's tables (each code span in it), outside ``## heading``."""
    out, inside = [], False
    for i, line in enumerate(doc.splitlines(), 1):
        if line.startswith("## "):
            inside = line[3:].strip() == heading
            continue
        if inside or not line.startswith("| ") or line.startswith("| message") or line.startswith("|---"):
            continue
        first = line[2:].split(" | ", 1)[0]
        for m in _SPAN.finditer(first):
            out.append(Entry(m.group(1) or m.group(2), "", i))
    return out


@functools.lru_cache(maxsize=None)
def _bases(sources: tuple = SOURCES) -> dict[str, list]:
    return {d.name: [ast.unparse(b).split(".")[-1] for b in d.bases]
            for _, t in _trees(sources) for d in ast.walk(t) if isinstance(d, ast.ClassDef)}


@functools.lru_cache(maxsize=None)
def subclass_of(cls: str, section: str) -> bool:
    """Whether a message of class ``cls`` belongs under the doc's ``### section``: ``cls`` is ``section`` or
    derives from it (in the source)."""
    if cls in (section, ANY_CLASS):
        return True
    return any(subclass_of(b, section) for b in _bases().get(cls, []))


#: the doc section that lists every message
CATALOG = "Every message, by kind"


def compare(doc: str, found: dict[tuple, Pattern]) -> tuple[list[Pattern], list[Entry]]:
    """(messages of the code no catalog entry of their kind matches, catalog entries no message of their kind
    matches). ``found``: :func:`messages`."""
    entries = catalog_entries(doc, CATALOG)

    def listed(p: Pattern, e: Entry) -> bool:
        return subclass_of(p.cls, e.section) and p.matches(e.text)

    missing = [p for p in found.values() if not any(listed(p, e) for e in entries)]
    stale = [e for e in entries if not any(listed(p, e) for p in found.values())]
    return missing, stale

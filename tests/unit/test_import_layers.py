"""The package's import graph: no cycles (function-local imports included) and the layers of
CONTRIBUTING.md (motion/metrics at the bottom, the runtime below the models, the CLI on top).

Read from the source with ``ast`` (nothing is imported), so a cycle hidden in a function body counts too.
"""

from __future__ import annotations

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[2] / "jaxgest"

# (importer prefix, forbidden import prefixes)
TOP = ("jaxgest.tgst", "jaxgest.zeggs", "jaxgest.cli", "jaxgest.commands", "jaxgest.pipeline", "jaxgest.bench")
LAYERS = [
    ("jaxgest.runtime", TOP + ("jaxgest.motion", "jaxgest.metrics", "jaxgest.kernels")),
    ("jaxgest.motion", TOP + ("jaxgest.metrics",)),
    ("jaxgest.motion", ("jaxgest.tgst", "jaxgest.zeggs", "jaxgest.cli", "jaxgest.commands", "jaxgest.pipeline")),
    ("jaxgest.metrics", ("jaxgest.tgst", "jaxgest.zeggs", "jaxgest.cli", "jaxgest.commands", "jaxgest.pipeline")),
    ("jaxgest.runtime", ("jaxgest.tgst", "jaxgest.zeggs", "jaxgest.cli", "jaxgest.commands", "jaxgest.pipeline")),
    ("jaxgest.kernels", ("jaxgest.tgst", "jaxgest.zeggs", "jaxgest.cli", "jaxgest.commands")),
    ("jaxgest.tgst", ("jaxgest.zeggs", "jaxgest.cli", "jaxgest.commands", "jaxgest.pipeline")),
    ("jaxgest.zeggs", ("jaxgest.tgst", "jaxgest.cli", "jaxgest.commands", "jaxgest.pipeline")),
]


def modules(package: pathlib.Path) -> dict[str, pathlib.Path]:
    out = {}
    for path in package.rglob("*.py"):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def import_graph(package: pathlib.Path) -> dict[str, set[str]]:
    """module -> the package modules it imports anywhere in its source (top level or inside functions).
    ``from a import b`` counts as an import of ``a.b`` when that is a module, of ``a`` otherwise; the parent
    packages Python runs implicitly are not edges."""
    mods = modules(package)
    root = package.name
    graph = {}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    target = alias.name
                    while target and target not in mods:
                        target = target.rpartition(".")[0]
                    if target:
                        edges.add(target)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[:len(base) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                if source != root and not source.startswith(root + "."):
                    continue
                for alias in node.names:
                    full = f"{source}.{alias.name}"
                    edges.add(full if full in mods else source)
        edges.discard(name)
        graph[name] = {e for e in edges if e in mods}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[v] = min(low[v], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                if len(component) > 1:
                    out.append(sorted(component))
    return out


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def test_no_import_cycle():
    found = cycles(import_graph(PACKAGE))
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_layers():
    graph = import_graph(PACKAGE)
    bad = [f"{m} imports {t}" for m, targets in sorted(graph.items()) for low_layer, forbidden in LAYERS
           if _under(m, low_layer) for t in sorted(targets) if any(_under(t, f) for f in forbidden)]
    assert not bad, "layering broken: " + "; ".join(bad)


def test_the_checks_can_fail(tmp_path):
    """Controls: a cycle through a function-local import and a relative import is found; a layering
    violation is reported."""
    pkg = tmp_path / "jaxgest"
    (pkg / "motion").mkdir(parents=True)
    (pkg / "tgst").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "motion" / "__init__.py").write_text("")
    (pkg / "tgst" / "__init__.py").write_text("")
    (pkg / "motion" / "a.py").write_text("def f():\n    from jaxgest.motion import b\n")
    (pkg / "motion" / "b.py").write_text("from . import a\n")
    (pkg / "motion" / "c.py").write_text("import jaxgest.tgst.model\n")
    (pkg / "tgst" / "model.py").write_text("from jaxgest.motion.a import f\n")
    graph = import_graph(pkg)
    assert cycles(graph) == [["jaxgest.motion.a", "jaxgest.motion.b"]]
    assert "jaxgest.tgst.model" in graph["jaxgest.motion.c"]


@pytest.mark.parametrize("name", ["jaxgest.runtime", "jaxgest.kernels", "jaxgest.motion", "jaxgest.metrics"])
def test_layer_packages_exist(name):
    assert name in modules(PACKAGE)

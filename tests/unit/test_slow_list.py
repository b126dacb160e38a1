"""tests/slow.txt (the tests that the README's test command leaves to .ci/run) names only files and test
functions that exist, and the marking reaches them: a stale entry would silently put nothing in the slow set,
a typo would leave a slow test in the fast one."""

from __future__ import annotations

import ast
import types

from conftest import REPO, is_listed_slow, slow_entries


def _test_functions(path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    return {n.name for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
            and n.name.startswith("test")}


def test_every_entry_exists():
    files, functions = slow_entries()
    assert files and functions
    for path in files | {p for p, _ in functions}:
        assert (REPO / path).is_file(), f"tests/slow.txt: {path}: no such test file"
        assert path.startswith("tests/") and path.endswith(".py"), path
    for path, function in functions:
        assert path not in files, f"tests/slow.txt: {path}::{function} is already in by its file"
        assert function in _test_functions(REPO / path), f"tests/slow.txt: {path}: no test function {function}"


def test_listed_tests_are_recognised_by_file_function_and_parametrization():
    """What the collection hook marks: a listed file's every test, a listed function's every case, no other."""
    entries = ({"tests/integration/test_resume_kill.py"},
               {("tests/integration/test_cli_data.py", "test_synth_then_render")})

    def item(path, name, originalname=None):
        return types.SimpleNamespace(path=REPO / path, name=name, originalname=originalname or name)

    assert is_listed_slow(item("tests/integration/test_resume_kill.py", "test_any[a-1]", "test_any"), entries)
    assert is_listed_slow(item("tests/integration/test_cli_data.py", "test_synth_then_render"), entries)
    assert is_listed_slow(item("tests/integration/test_cli_data.py", "test_synth_then_render[x]",
                               "test_synth_then_render"), entries)
    assert not is_listed_slow(item("tests/integration/test_cli_data.py", "test_synth_then_render_fast"), entries)
    assert not is_listed_slow(item("tests/unit/test_resume_kill.py", "test_anything"), entries)


def test_this_run_marks_what_the_list_names(request):
    """In this session, every collected test that the list names carries ``slow``; this one does not."""
    entries = slow_entries()
    assert all(i.get_closest_marker("slow") for i in request.session.items if is_listed_slow(i, entries))
    assert request.node.get_closest_marker("slow") is None

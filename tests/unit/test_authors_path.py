"""``their_code_on_path``: the authors' folder leads sys.path only inside, and their generically named modules
leave sys.modules on exit (a leaked ``modules`` once made a later test see the wrong module)."""

from __future__ import annotations

import importlib
import sys

from jaxgest.zeggs.authors_path import their_code_on_path


def test_their_modules_leave_with_their_path(tmp_path):
    (tmp_path / "anim").mkdir()
    (tmp_path / "anim" / "__init__.py").write_text("")
    (tmp_path / "anim" / "tquat.py").write_text("def double(x):\n    return 2 * x\n")
    (tmp_path / "modules.py").write_text("from anim.tquat import *\n\nclass Net:\n    def f(self, x):\n"
                                         "        return double(x) + 1\n")
    path_before, mods_before = list(sys.path), set(sys.modules)
    assert "modules" not in sys.modules
    with their_code_on_path(tmp_path) as root:
        assert sys.path[0] == root == str(tmp_path.resolve())
        mod = importlib.import_module("modules")
        assert {"modules", "anim", "anim.tquat"} <= set(sys.modules)
    assert sys.path == path_before
    assert not {"modules", "anim", "anim.tquat"} & set(sys.modules)
    assert set(sys.modules) - mods_before == set()
    assert mod.Net().f(3) == 7  # what was made inside keeps working


def test_their_modules_leave_when_the_import_fails(tmp_path):
    (tmp_path / "helpers.py").write_text("X = 1\n")
    (tmp_path / "broken.py").write_text("import helpers\nraise RuntimeError('boom')\n")
    path_before = list(sys.path)
    try:
        with their_code_on_path(tmp_path):
            importlib.import_module("broken")
    except RuntimeError:
        pass
    assert sys.path == path_before and "helpers" not in sys.modules and "broken" not in sys.modules

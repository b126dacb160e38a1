"""Benchmark case registry.

Each module in this package exposes ``cases(quick: bool) -> list[harness.Case]``; :func:`all_cases`
collects them in the order of ``MODULES``. To add a case: write a function building a
:class:`benchmarks.harness.Case` (same weights for every implementation, ``make_args`` builds the inputs
once), return it from your module's ``cases``, and add the module name here if it is new. Modules whose
imports fail because a model does not exist yet are skipped with a note.
"""

from __future__ import annotations

import importlib

MODULES = ("benchmarks.cases.tgst", "benchmarks.cases.zeggs", "benchmarks.cases.train")


def all_cases(quick: bool = False, log=print) -> list:
    out = []
    for name in MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name and (e.name == name or e.name.startswith("jaxgest.")):
                log(f"  (skipping {name}: {e.name} is not available)")
                continue
            raise
        out.extend(module.cases(quick))
    return out

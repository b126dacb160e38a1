"""Benchmark case registry: every module of this package that defines ``cases(quick)`` is picked up.

How to add a case
-----------------
1. Create (or extend) a module here, e.g. ``jaxgest/bench/cases/zeggs.py``, defining
   ``cases(quick: bool) -> list[jaxgest.bench.harness.Case]``. Nothing else needs registering: modules are
   discovered by :func:`all_cases` in alphabetical order (``_``-prefixed modules are skipped).
2. Build each :class:`~jaxgest.bench.harness.Case` with ``name`` (unique, used by ``--cases``), ``batch``,
   ``frames`` (``poses`` if a call produces something other than batch x frames poses), ``impls`` and
   ``make_args`` -- a function returning the argument tuple passed to every implementation (weights and
   inputs built once; every implementation gets the same weights).
3. Implementations are :class:`~jaxgest.bench.harness.Impl`: ``Impl("jit", jax.jit(f), kind="jit")`` (trace
   / lower / compile timed apart; bind static arguments with ``functools.partial`` before ``jax.jit``),
   ``Impl("eager", f_under_disable_jit)``, ``Impl("numpy", reference)``. Name them ``jit`` / ``eager`` /
   ``numpy`` so the report computes eager/jit and numpy/jit. The first implementation is the reference of
   the equality check; pick ``rtol``/``atol`` for float32 (1e-4 .. 1e-3).
4. Give a family of clip lengths one ``group`` (e.g. ``"tgst_scaling"``) to get it into ``--plot``; set
   ``quick=False`` on cases too slow for ``--quick`` (< 2 minutes for the whole quick suite on 2 cores),
   or return fewer cases from ``cases(quick=True)``.

A module whose import fails because a ``jaxgest`` model module does not exist yet (or lacks a name) is
skipped with a note; any other import error is a bug and propagates.

The model cases live in ``tgst`` (transfer, clip-length scaling, stages), ``zeggs`` (generation per frame,
style encoder, speech encoder and features), ``training`` (one optimiser step per model),
``zeggs_variants`` (benchmark-local generator optimisation experiments, full run only), ``peers``
(side by side with eager and compiled (``torch.compile``) PyTorch ports of the authors' networks, interleaved
rounds; weight formats of the ZeroEGGS generator) and ``peers_train`` (TGST and ZeroEGGS training steps side by side
with eager and compiled PyTorch training steps). ``jaxgest bench --cases peer_`` runs both peer modules.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Callable


def case_modules() -> list[str]:
    """Fully qualified names of the case modules in this package, alphabetical."""
    return sorted(f"{__name__}.{m.name}" for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def all_cases(quick: bool = False, log: Callable[[str], None] = print) -> list:
    """Every case of every case module (``cases(quick)``), in module order; duplicate names are a bug."""
    out = []
    for name in case_modules():
        try:
            module = importlib.import_module(name)
        except ImportError as e:  # ModuleNotFoundError included
            missing = e.name or ""
            if missing.startswith("jaxgest"):
                log(f"  (skipping {name}: {missing} is not available yet: {e})")
                continue
            raise
        if not hasattr(module, "cases"):
            continue
        out.extend(module.cases(quick))
    seen: set = set()
    for case in out:
        if case.name in seen:
            raise ValueError(f"benchmark case name {case.name!r} is registered twice")
        seen.add(case.name)
    return out

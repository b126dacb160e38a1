"""Run the ZeroEGGS authors' own code (``../shared/third_party/zeggs-official``, verbatim) inside a test.

The authors' code is read where it lies (never copied or modified: CC BY-NC-ND). It predates current numpy,
scipy and torch; three shims make it run unchanged, each applied only while :func:`authors_code` is active:

* ``torch.load`` of their whole pickled modules needs ``weights_only=False`` (torch >= 2.6 defaults to True);
* ``scipy.signal.hann`` moved to ``scipy.signal.windows.hann`` (their ``audio/spectrograms.py``);
* ``np.float`` / ``np.int`` / ``np.bool`` / ``np.complex`` / ``np.object`` were removed in numpy 1.24.

``require_authors()`` skips the calling test with its reason (no shared folder, no torch, a missing Python
package of theirs). Their modules are imported under their own top-level names (``modules``, ``generate``,
``data_pipeline``, ``anim``, ``audio``), so a test that uses them imports them inside :func:`authors_code`.
"""

from __future__ import annotations

import builtins
import contextlib
import importlib
import importlib.util
import os
import pathlib
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
SHARED = pathlib.Path(os.environ.get("JAXGEST_SHARED", REPO.parent / "shared")).resolve()
OFFICIAL = SHARED / "third_party" / "zeggs-official"
ZEGGS_CODE = OFFICIAL / "ZEGGS"
#: Their top-level module names; removed from sys.modules on exit so that nothing leaks between tests
#: (``audio`` in particular would shadow a project module of that name).
_THEIR_MODULES = ("modules", "generate", "data_pipeline", "dataset", "helpers", "utils", "optimizers", "train",
                  "anim", "audio")
#: The Python packages their generate / data pipeline import (from PyPI; jaxgest's [authors] extra). ``sox``
#: (pysox) is imported by their ``audio/audio_files.py``; it calls the SoX program only to resample.
AUTHORS_PACKAGES = ("torch", "pandas", "omegaconf", "rich", "scipy", "pyloudnorm", "sox")


def missing_reason() -> str | None:
    """Why the authors' code cannot run here (None when it can)."""
    if not (ZEGGS_CODE / "modules.py").is_file():
        return f"the authors' ZeroEGGS code is not at {ZEGGS_CODE} (../shared/third_party/zeggs-official)"
    missing = [p for p in AUTHORS_PACKAGES if importlib.util.find_spec(p) is None]
    if missing:
        return ("the authors' code needs " + ", ".join(missing)
                + " (.ci/run installs them; pip install 'jaxgest[authors]')")
    return None


def require_authors() -> None:
    """Skip the calling test, with its reason, when the authors' code cannot run here."""
    reason = missing_reason()
    if reason:
        pytest.skip(reason)


@contextlib.contextmanager
def authors_code():
    """Context in which the authors' modules import and run (their folder on sys.path, the shims above)."""
    require_authors()
    import numpy as np
    import scipy.signal
    import scipy.signal.windows
    import torch

    saved_path = list(sys.path)
    saved_modules = {k: v for k, v in sys.modules.items() if k.split(".")[0] in _THEIR_MODULES}
    np_names = {"float": builtins.float, "int": builtins.int, "bool": builtins.bool,
                "complex": builtins.complex, "object": builtins.object}
    added_np = [n for n in np_names if n not in np.__dict__]
    had_hann = hasattr(scipy.signal, "hann")
    real_load = torch.load

    def load(*args, **kw):
        kw.setdefault("weights_only", False)
        return real_load(*args, **kw)

    for k in saved_modules:
        del sys.modules[k]
    sys.path.insert(0, str(ZEGGS_CODE))
    for n in added_np:
        setattr(np, n, np_names[n])
    if not had_hann:
        scipy.signal.hann = scipy.signal.windows.hann
    torch.load = load
    try:
        yield
    finally:
        torch.load = real_load
        if not had_hann:
            del scipy.signal.hann
        for n in added_np:
            delattr(np, n)
        sys.path[:] = saved_path
        for k in [k for k in sys.modules if k.split(".")[0] in _THEIR_MODULES]:
            del sys.modules[k]
        sys.modules.update(saved_modules)


def their(name: str):
    """Import one of the authors' modules by its top-level name (inside :func:`authors_code`)."""
    return importlib.import_module(name)


def released(version: str, name: str) -> pathlib.Path:
    """Path of a released file of v1 / v2, e.g. ``released("v1", "speech_encoder.pt")`` or ``"stats.npz"``."""
    if name.endswith(".pt"):
        return OFFICIAL / "data" / "outputs" / version / "saved_models" / name
    if name == "options.json":
        return OFFICIAL / "data" / "outputs" / version / name
    return OFFICIAL / "data" / f"processed_{version}" / name

"""The ZeroEGGS authors' code folder on ``sys.path`` for one import or unpickling, and nothing left behind.

Their modules have generic top-level names (``modules``, ``anim``, ``audio``, ``helpers``) that would shadow
other packages' modules of those names for the rest of the process. Inside :func:`their_code_on_path` their
``ZEGGS/`` folder leads ``sys.path``; on exit the path is restored and every module imported meanwhile from
that folder leaves ``sys.modules`` (objects already made keep working: their functions hold their globals).
Used by the release importer, the speech-encoder converter and the benchmark of their decoder.

References: Ghorbani et al. 2023 (the authors' repository ubisoft/ubisoft-laforge-ZeroEGGS, ``ZEGGS/``).
"""

from __future__ import annotations

import contextlib
import pathlib
import sys


@contextlib.contextmanager
def their_code_on_path(code_dir):
    """``code_dir`` (their ``ZEGGS/`` folder) first on ``sys.path`` while inside; see the module doc."""
    root = str(pathlib.Path(code_dir).resolve())
    saved, before = list(sys.path), set(sys.modules)
    sys.path.insert(0, root)
    try:
        yield root
    finally:
        sys.path[:] = saved
        for k in set(sys.modules) - before:
            if str(getattr(sys.modules[k], "__file__", "") or "").startswith(root):
                del sys.modules[k]

"""An explicit, caller-owned cache of models loaded from workdirs (no module-level state)."""

from __future__ import annotations

import pathlib
from typing import Any, Callable

__all__ = ["ModelCache"]


class ModelCache:
    """An explicit cache of models loaded from workdirs, reloaded when a workdir's checkpoints change.

    ``load(workdir)`` loads a model; ``version(workdir)`` is a cheap, hashable description of the workdir's
    checkpoints (a directory listing, no arrays read). ``get(workdir)`` returns the cached model while the
    version is unchanged and loads again otherwise (dropping that workdir's older versions); at most
    ``maxsize`` models are kept, least recently used dropped first. Owned by its caller.
    """

    def __init__(self, load: Callable[[Any], Any], version: Callable[[Any], Any], maxsize: int):
        self._load, self._version, self.maxsize = load, version, int(maxsize)
        self._models: dict = {}

    def get(self, workdir):
        path = str(pathlib.Path(workdir).resolve())
        key = (path, self._version(workdir))
        model = self._models.pop(key, None)
        if model is None:
            model = self._load(workdir)
            self._models = {k: v for k, v in self._models.items() if k[0] != path}  # its older versions
        self._models[key] = model  # most recently used last
        while len(self._models) > self.maxsize:
            self._models.pop(next(iter(self._models)))
        return model

    def clear(self) -> None:
        self._models.clear()

"""Build the next training batches on a background thread while the device runs the current step.

:func:`jaxgest.training.train_loop` asks for the batch of step ``i`` right after dispatching step ``i - 1``
(asynchronously); without prefetching, the host builds batch ``i`` (NumPy indexing, random windows,
``device_put``) on the Python thread before it can dispatch step ``i``, and on a 2-core machine the
next dispatch waits for it. :class:`Prefetcher` runs ``batch_fn`` for the next ``depth`` steps on one
worker thread. ``batch_fn(i)`` is a pure function of ``i`` (the loop's contract), so the batches -- and
the whole run, bit for bit -- are the same as without prefetching; only their timing changes.

An exception of ``batch_fn`` is raised by :meth:`Prefetcher.get` for the step that caused it (the step
before it still runs), as without prefetching.
"""

from __future__ import annotations

import concurrent.futures
from collections.abc import Callable
from typing import Any


class Prefetcher:
    """``get(i)``: the batch of step ``i``; steps ``i + 1 .. i + depth`` are then already being built.

    Steps must be asked for in increasing order (any other request is built on the spot). The worker
    stops after the batch of the last step (``stop - 1``) is handed out, or at ``close()`` (or the end of
    the ``with`` block); batches built for steps never asked for are dropped.
    """

    def __init__(self, batch_fn: Callable[[int], Any], *, stop: int, depth: int = 1):
        if depth < 1:
            raise ValueError(f"prefetch depth must be >= 1, got {depth}")
        self.batch_fn, self.stop, self.depth = batch_fn, int(stop), int(depth)
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="jaxgest-prefetch")
        self._pending: dict[int, concurrent.futures.Future] = {}

    def _submit(self, i: int) -> None:
        if i < self.stop and i not in self._pending:
            self._pending[i] = self._pool.submit(self.batch_fn, i)

    def get(self, i: int) -> Any:
        future = self._pending.pop(i, None)
        for j in [j for j in self._pending if j < i]:  # skipped steps: not needed any more
            self._pending.pop(j).cancel()
        for j in range(i + 1, i + 1 + self.depth):
            self._submit(j)
        try:
            return future.result() if future is not None else self.batch_fn(i)
        finally:
            if i + 1 >= self.stop:  # the last step: nothing more to build, let the worker go
                self.close(wait=False)

    def close(self, wait: bool = True) -> None:
        for f in self._pending.values():
            f.cancel()
        self._pending.clear()
        self._pool.shutdown(wait=wait)

    def __enter__(self) -> "Prefetcher":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

"""The training loop's batch prefetcher hands out exactly the batches of ``batch_fn`` (same steps, same
values), raises ``batch_fn``'s error at the step that caused it, and stops its worker after the last step."""

from __future__ import annotations

import threading

import pytest

from jaxgest.prefetch import Prefetcher


def test_prefetched_batches_are_batch_fn_of_each_step_and_built_ahead():
    calls = []

    def batch_fn(i):
        calls.append((i, threading.current_thread().name))
        return {"step": i}

    pf = Prefetcher(batch_fn, stop=5, depth=2)
    assert [pf.get(i)["step"] for i in range(5)] == list(range(5))
    assert sorted(i for i, _ in calls) == list(range(5))  # each step built once, nothing past the stop
    assert any(name.startswith("jaxgest-prefetch") for _, name in calls)  # steps 1.. on the worker
    assert pf._pool._shutdown  # the worker was let go after the last step


def test_a_batch_error_is_raised_for_its_own_step():
    def batch_fn(i):
        if i == 2:
            raise ValueError("bad clip at step 2")
        return i

    with Prefetcher(batch_fn, stop=10) as pf:
        assert pf.get(0) == 0 and pf.get(1) == 1
        with pytest.raises(ValueError, match="step 2"):
            pf.get(2)


def test_a_resumed_or_skipping_caller_gets_the_right_batches():
    with Prefetcher(lambda i: i * 10, stop=100, depth=1) as pf:
        assert pf.get(40) == 400 and pf.get(41) == 410 and pf.get(45) == 450 and pf.get(46) == 460
    with pytest.raises(ValueError, match="depth"):
        Prefetcher(lambda i: i, stop=3, depth=0)

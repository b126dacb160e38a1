"""Shared training machinery: checkpoint save/restore/resume, config check, metrics.jsonl, NaN stop."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxgest.runtime.errors import CheckpointError, TrainingError
from jaxgest.runtime.training import Checkpointer, MetricsLogger, TrainState, config_diff, train_loop


def _toy(lr=0.1):
    params = {"w": jnp.zeros((3,), jnp.float32), "b": jnp.zeros((), jnp.float32)}
    tx = optax.adam(lr)
    state = TrainState.create(apply_fn=None, params=params, tx=tx)
    target = jnp.asarray([1.0, -2.0, 0.5], jnp.float32)

    @jax.jit
    def step(state, batch, key):
        def loss_fn(p):
            pred = batch["x"] @ p["w"] + p["b"]
            return jnp.mean((pred - batch["x"] @ target) ** 2) * batch["scale"]

        loss, grads = jax.value_and_grad(loss_fn)(state.params)
        return state.apply_gradients(grads=grads), {"loss": loss}

    def batch_fn(i):
        rng = np.random.default_rng(i)
        return {"x": jnp.asarray(rng.normal(size=(8, 3)), jnp.float32), "scale": jnp.float32(1.0)}

    return state, step, batch_fn


def test_loss_decreases_and_metrics_written(tmp_path, key):
    state, step, batch_fn = _toy()
    log = MetricsLogger(tmp_path)
    state = train_loop(state, step, batch_fn, key=key, num_steps=40, logger=log, log_every=10, progress=False)
    lines = [json.loads(x) for x in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in lines] == [10, 20, 30, 40]
    assert lines[-1]["loss"] < lines[0]["loss"]


def test_resume_equals_uninterrupted(tmp_path, key):
    cfg = {"lr": 0.1, "steps": 30}
    s0, step, batch_fn = _toy()
    full = train_loop(s0, step, batch_fn, key=key, num_steps=30, progress=False)

    ck = Checkpointer(tmp_path, kind="toy", config=cfg)
    s1, _, _ = _toy()
    train_loop(s1, step, batch_fn, key=key, num_steps=20, checkpointer=ck, ckpt_every=10, progress=False)
    ck.close()
    # "Killed" after step 20; a new process restores and continues.
    ck2 = Checkpointer(tmp_path, kind="toy", config={**cfg, "steps": 30})
    assert ck2.latest_step() == 20
    s2, _, _ = _toy()
    s2 = ck2.restore(s2)
    assert int(s2.step) == 20
    resumed = train_loop(s2, step, batch_fn, key=key, num_steps=30, checkpointer=ck2, progress=False)
    ck2.close()
    np.testing.assert_array_equal(np.asarray(resumed.params["w"]), np.asarray(full.params["w"]))


def test_restore_with_other_config_names_the_difference(tmp_path, key):
    s, step, batch_fn = _toy()
    ck = Checkpointer(tmp_path, kind="toy", config={"lr": 0.1, "width": 3})
    ck.save(s)
    ck.close()
    other = Checkpointer(tmp_path, kind="toy", config={"lr": 0.1, "width": 4})
    with pytest.raises(CheckpointError, match=r"width: 3 -> 4"):
        other.restore(s)
    wrong_kind = Checkpointer(tmp_path, kind="other", config={"lr": 0.1, "width": 3})
    with pytest.raises(CheckpointError, match="model kind"):
        wrong_kind.restore(s)


def test_missing_checkpoint_is_a_clear_error(tmp_path):
    with pytest.raises(CheckpointError, match="no checkpoint"):
        Checkpointer(tmp_path / "nothing", kind="toy", config={}, read_only=True)


def test_non_finite_loss_stops_and_keeps_last_good(tmp_path, key):
    s, step, batch_fn = _toy()
    ck = Checkpointer(tmp_path, kind="toy", config={})

    def bad_batch(i):
        b = batch_fn(i)
        return {**b, "scale": jnp.float32(np.nan if i >= 12 else 1.0)}

    with pytest.raises(TrainingError, match="non-finite loss at step"):
        train_loop(s, step, bad_batch, key=key, num_steps=30, checkpointer=ck, ckpt_every=5, log_every=5,
                   progress=False)
    assert ck.latest_step() == 10
    restored = ck.restore(_toy()[0])
    assert np.all(np.isfinite(np.asarray(restored.params["w"])))
    ck.close()


def test_config_diff_nested():
    assert config_diff({"a": 1, "m": {"x": 1}}, {"a": 1, "m": {"x": 2}}) == ["m.x: 1 -> 2"]
    assert config_diff({"a": 1}, {"a": 1}) == []


def test_checkpointer_has_no_process_wide_side_effects(tmp_path, monkeypatch):
    """The unraisable-hook filter lives only while a Checkpointer is open; absl's level is left as it was.
    (``jaxgest.cli.main`` installs the filter for its whole process, so the test starts from a clean state.)"""
    import logging
    import sys

    from jaxgest.runtime import orbax_noise

    def hook(unraisable):  # stands for whatever the process had installed
        pass

    monkeypatch.setattr(orbax_noise, "_MUTE_DEPTH", 0)
    monkeypatch.setattr(sys, "unraisablehook", hook)
    level = logging.getLogger("absl").level
    ck = Checkpointer(tmp_path, kind="toy", config={"lr": 0.1})
    assert sys.unraisablehook is orbax_noise._closed_loop_hook  # installed while open
    with Checkpointer(tmp_path, kind="toy", config={"lr": 0.1}, read_only=True) as ro:  # nested: one filter
        assert ro.latest_step() is None
    assert sys.unraisablehook is orbax_noise._closed_loop_hook
    ck.close()
    assert sys.unraisablehook is hook and logging.getLogger("absl").level == level
    with orbax_noise.closed_loop_errors_muted():
        seen = []
        sys.unraisablehook = seen.append  # someone else replaces it meanwhile
    assert sys.unraisablehook == seen.append  # not clobbered on exit


def test_orphan_tensorstore_task_records_are_dropped_only_while_muted(caplog, monkeypatch, request):
    """asyncio's "Task exception was never retrieved" of an abandoned tensorstore read (the noise of a damaged
    checkpoint: it surfaced at garbage collection in a `tgst transfer` process) is dropped while the filter is
    installed; an unrelated task's record still passes, and nothing is dropped after the context ends."""
    import asyncio
    import gc
    import logging
    import sys

    from jaxgest.runtime import orbax_noise

    def orphan(message):
        async def fail():
            raise ValueError(message)

        loop = asyncio.new_event_loop()
        task = loop.create_task(fail())
        loop.run_until_complete(asyncio.sleep(0))
        assert task.done()
        del task
        loop.close()
        gc.collect()

    # start from no open context (an in-process `jaxgest.cli.main` of another test keeps one open for the
    # process); the filter is put back afterwards if it was there
    logger = logging.getLogger("asyncio")
    was_there = orbax_noise._ORPHAN_FILTER in logger.filters
    monkeypatch.setattr(orbax_noise, "_MUTE_DEPTH", 0)
    monkeypatch.setattr(orbax_noise, "_MUTE_PREVIOUS", orbax_noise._MUTE_PREVIOUS)
    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)
    logger.removeFilter(orbax_noise._ORPHAN_FILTER)
    request.addfinalizer(lambda: logger.addFilter(orbax_noise._ORPHAN_FILTER) if was_there else None)
    noise = "OUT_OF_RANGE: Error reading byte range [tensorstore_spec='{\"driver\":\"zarr\"}']"
    with caplog.at_level("ERROR", logger="asyncio"):
        with orbax_noise.closed_loop_errors_muted():
            orphan(noise)
            orphan("a real bug in user code")
        assert [r.exc_info[1].args[0] for r in caplog.records] == ["a real bug in user code"]
        caplog.clear()
        orphan(noise)  # the filter is gone with the context
        assert [r.exc_info[1].args[0] for r in caplog.records] == [noise]

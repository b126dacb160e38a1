"""Training you can watch (issue 60, part B) in jaxgest.runtime.training: logged metrics as means over the log
interval, a held-out loss every ``eval_every`` steps, the TensorBoard writer behind ``MetricsLogger.log`` and
the profiler window. A toy step whose metric is its own step index, so every mean is known exactly."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import optax
import pytest

from jaxgest.runtime.errors import TrainingError
from jaxgest.runtime.training import MetricsLogger, TrainState, train_loop
from tb_events import scalar_events


def _counting_state():
    return TrainState.create(apply_fn=None, params={"w": jnp.zeros((2,), jnp.float32)}, tx=optax.sgd(0.0))


@jax.jit
def _counting_step(state, batch, key):
    """Metrics: ``index`` = the step's index (0-based), ``x`` = the batch's value."""
    metrics = {"index": state.step.astype(jnp.float32), "x": batch}
    return state.replace(step=state.step + 1), metrics


def _batch(i):
    return jnp.float32(10.0 * i)


def _lines(path):
    return [json.loads(x) for x in (path / "metrics.jsonl").read_text().splitlines()]


def test_logged_metrics_are_interval_means(tmp_path, key):
    train_loop(_counting_state(), _counting_step, _batch, key=key, num_steps=10,
               logger=MetricsLogger(tmp_path),
               log_every=4, progress=False)
    lines = _lines(tmp_path)
    assert [r["step"] for r in lines] == [4, 8, 10]
    # means over steps 0-3, 4-7 and the last, shorter interval 8-9 (not the value at the log step: 3, 7, 9)
    assert [r["index"] for r in lines] == [1.5, 5.5, 8.5]
    assert [r["x"] for r in lines] == [15.0, 55.0, 85.0]


def test_interval_after_a_resume_starts_at_the_resume(tmp_path, key):
    state = _counting_state().replace(step=jnp.asarray(6, jnp.int32))  # as restored from a step-6 checkpoint
    train_loop(state, _counting_step, _batch, key=key, num_steps=12, logger=MetricsLogger(tmp_path),
               log_every=4, progress=False)
    assert [(r["step"], r["index"]) for r in _lines(tmp_path)] == [(8, 6.5), (12, 9.5)]


def test_held_out_metrics_join_the_log_line(tmp_path, key):
    seen = []

    def eval_fn(state):
        seen.append(int(state.step))
        return {"loss": state.step.astype(jnp.float32) * 2}

    train_loop(_counting_state(), _counting_step, _batch, key=key, num_steps=10,
               logger=MetricsLogger(tmp_path),
               log_every=2, eval_every=4, eval_fn=eval_fn, progress=False)
    lines = _lines(tmp_path)
    assert seen == [4, 8, 10]  # the multiples of eval_every, and the last step
    assert {r["step"]: r.get("eval_loss") for r in lines} == {2: None, 4: 8.0, 6: None, 8: 16.0, 10: 20.0}
    assert all("index" in r for r in lines)  # held-out lines still carry the training metrics
    with pytest.raises(ValueError, match="together"):
        train_loop(_counting_state(), _counting_step, _batch, key=key, num_steps=2, eval_every=2,
                   progress=False)
    with pytest.raises(TrainingError, match="eval_every must be a positive"):
        train_loop(_counting_state(), _counting_step, _batch, key=key, num_steps=2, eval_every=0,
                   eval_fn=eval_fn, progress=False)


def test_non_finite_step_inside_an_interval_stops_at_its_log_step(tmp_path, key):
    @jax.jit
    def step(state, batch, key):  # the loss is NaN at step index 1 only; the log step (index 3) is finite
        loss = jnp.where(state.step == 1, jnp.nan, 1.0)
        return state.replace(step=state.step + 1), {"loss": loss}

    with pytest.raises(TrainingError, match="non-finite loss at step 4"):
        train_loop(_counting_state(), step, _batch, key=key, num_steps=8, logger=MetricsLogger(tmp_path),
                   log_every=4, progress=False)
    assert not (tmp_path / "metrics.jsonl").exists() or _lines(tmp_path) == []


def test_tensorboard_writer_behind_log(tmp_path, key):
    pytest.importorskip("tensorboardX")
    logger = MetricsLogger(tmp_path, extra={"stage": "toy", "devices": 1}, tb_dir=tmp_path / "tb")
    train_loop(_counting_state(), _counting_step, _batch, key=key, num_steps=4, logger=logger, log_every=2,
               eval_every=4, eval_fn=lambda s: {"index": jnp.float32(-1.0)}, progress=False)
    logger.close()
    got = {(run, tag, step): value for run, tag, step, value in scalar_events(tmp_path / "tb")}
    # the same numbers as metrics.jsonl: training ones in train/, held-out ones in eval/ under the same tag
    for r in _lines(tmp_path):
        assert got[("train", "toy/index", r["step"])] == r["index"]
        assert got[("train", "toy/x", r["step"])] == r["x"]
    assert got[("eval", "toy/index", 4)] == -1.0
    assert ("eval", "toy/index", 2) not in got
    assert not [k for k in got if k[1] in ("toy/devices", "toy/stage")]  # a line's fixed fields: not metrics


def test_profile_traces_a_few_steps(tmp_path, key):
    train_loop(_counting_state(), _counting_step, _batch, key=key, num_steps=6, log_every=6,
               profile_dir=tmp_path / "prof", progress=False)
    traces = list((tmp_path / "prof").rglob("*.xplane.pb"))
    assert len(traces) == 1 and traces[0].stat().st_size > 0
    jax.profiler.start_trace(str(tmp_path / "again"))  # the loop's trace was stopped (one at a time)
    jax.profiler.stop_trace()
    # a run that fails inside the window stops its trace too
    def failing(state, batch, key):
        if int(state.step) == 2:
            raise RuntimeError("boom")
        return _counting_step(state, batch, key)

    with pytest.raises(RuntimeError, match="boom"):
        train_loop(_counting_state(), failing, _batch, key=key, num_steps=6, profile_dir=tmp_path / "p2",
                   progress=False)
    jax.profiler.start_trace(str(tmp_path / "again2"))
    jax.profiler.stop_trace()

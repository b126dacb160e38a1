"""Runs killed with SIGKILL resume from their last complete checkpoint and end like an uninterrupted run.

Subprocesses run the real command line (``python -m jaxgest.cli tgst train`` / ``zeggs train``, the code
behind the ``jaxgest`` script) on the session's tiny synthetic dataset. A run is killed once a complete checkpoint
exists (polling the checkpoint folder: orbax writes ``<step>.orbax-checkpoint-tmp-*`` and renames it to
``<step>`` when the save is complete), then restarted; the restored parameters of its final checkpoint
must equal, bit for bit, those of an uninterrupted run with the same seed -- the session's shared workdir
(tests/helpers/tiny_models.py, trained in-process on one device; the subprocesses pass ``--devices 1`` and the same
settings) -- and the metrics it logs after the restart must equal the uninterrupted run's lines. To make the kill independent of timing, the killed
run is asked for far more steps than it can reach before the kill; the restart asks for the reference's
step count (the requested step count is not part of the checkpoint check). The subprocesses share one
persistent XLA compilation cache so only the first run of each model compiles.

The kill *during* a save polls for orbax's temporary folder and kills as soon as it appears (every step
is checkpointed, so most of the run is spent saving); whether the kill landed inside the save is read
from the folder left behind, and the attempt is repeated a few times if it did not.

A non-finite loss (or non-finite parameters after a NaN gradient) stops :func:`jaxgest.runtime.training.train_loop`
with a one-line TrainingError and leaves the last good checkpoint as the latest one.
"""

from __future__ import annotations

import json
import os
import pathlib
import re
import signal
import subprocess
import sys
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxgest.runtime.errors import TrainingError
from jaxgest.runtime.training import Checkpointer, MetricsLogger, TrainState, train_loop

from conftest import NUM_DEVICES
from faults_testing import assert_identical, params_at
from tiny_models import CKPT_EVERY, TGST_STEPS, TINY_SEED, ZEGGS_STEPS

SEED = TINY_SEED
REPO = pathlib.Path(__file__).resolve().parents[2]
TMP_MARK = "orbax-checkpoint-tmp"


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    e = {k: v for k, v in os.environ.items() if not k.startswith(("XLA_", "JAX_PLATFORMS"))}
    e.setdefault("JAX_COMPILATION_CACHE_DIR", str(tmp_path_factory.mktemp("xla_cache")))
    e.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
    # the same CPU client as the test process (its device count changes how XLA splits the work, and with it
    # the last bits of the sums): the runs are compared bit for bit with the session's in-process workdirs
    e.update(JAX_PLATFORMS="cpu", JAX_NUM_CPU_DEVICES=str(NUM_DEVICES), PYTHONPATH=str(REPO),
             PYTHONUNBUFFERED="1")
    return e


@pytest.fixture(scope="module")
def data(tiny_data):
    return tiny_data


def _cmd(*args) -> list:
    return [sys.executable, "-m", "jaxgest.cli", *map(str, args)]


def _run(args, env, timeout=900) -> subprocess.CompletedProcess:
    r = subprocess.run(_cmd(*args), env=env, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def complete_steps(ckpt_dir: pathlib.Path) -> list:
    """Steps with a finalised checkpoint folder (orbax renames the temporary folder when done)."""
    if not ckpt_dir.is_dir():
        return []
    return sorted(int(p.name) for p in ckpt_dir.iterdir()
                  if p.name.isdigit() and (p / "_CHECKPOINT_METADATA").is_file())


def temporary_folders(ckpt_dir: pathlib.Path) -> list:
    return sorted(p.name for p in ckpt_dir.iterdir() if TMP_MARK in p.name) if ckpt_dir.is_dir() else []


def kill_when(args, env, ready, timeout=600.0, poll=0.002):
    """Start the command, SIGKILL it as soon as ``ready()`` is true; returns the process (must be killed)."""
    with tempfile.TemporaryFile("w+") as err:  # a file, not a pipe: a full pipe would block the run
        proc = subprocess.Popen(_cmd(*args), env=env, stdout=subprocess.DEVNULL, stderr=err, text=True)
        t0 = time.monotonic()
        try:
            while not ready():
                if proc.poll() is not None:
                    err.seek(0)
                    raise AssertionError(f"run ended before the kill (exit {proc.returncode}): "
                                         f"{err.read()[-2000:]}")
                if time.monotonic() - t0 > timeout:
                    raise AssertionError("no checkpoint appeared in time")
                time.sleep(poll)
            proc.send_signal(signal.SIGKILL)
        finally:
            if proc.poll() is None and not ready():
                proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return proc


def metrics(workdir: pathlib.Path) -> list:
    return [json.loads(x) for x in (workdir / "metrics.jsonl").read_text().splitlines()]


def _losses(lines, stage):
    return {r["step"]: {k: v for k, v in r.items() if k != "steps_per_s"}
            for r in lines if r["stage"] == stage}


# ----- TGST -------------------------------------------------------------------------------------------------

TGST_AE, TGST_TR = TGST_STEPS["ae_steps"], TGST_STEPS["transformer_steps"]


def _tgst(data, work, ae, tr, ckpt_every=CKPT_EVERY, log_every=1):
    return ["tgst", "train", "--data", data, "--workdir", work, "--preset", "tiny", "--seed", SEED,
            "--ae-steps", ae, "--transformer-steps", tr, "--ckpt-every", ckpt_every, "--log-every", log_every,
            "--devices", 1]


@pytest.fixture(scope="module")
def tgst_reference(tgst_workdir):
    """The uninterrupted run: the session's TGST workdir (same data, seed, steps and intervals)."""
    return tgst_workdir


@pytest.mark.slow
def test_tgst_killed_in_transformer_stage_resumes_to_the_same_parameters(data, env, tgst_reference, tmp_path):
    work = tmp_path / "w"
    tr_dir = work / "checkpoints" / "transformer"
    kill_when(_tgst(data, work, TGST_AE, 100_000), env, lambda: bool(complete_steps(tr_dir)))
    killed_at = complete_steps(tr_dir)[-1]
    assert CKPT_EVERY <= killed_at < TGST_TR, killed_at
    assert complete_steps(work / "checkpoints" / "autoencoder")[-1] == TGST_AE
    before = len(metrics(work))

    r = _run(_tgst(data, work, TGST_AE, TGST_TR), env)
    assert f"autoencoder already at step {TGST_AE}, nothing to do" in r.stdout, r.stdout
    new = metrics(work)[before:]
    assert [x["stage"] for x in new] == ["transformer"] * (TGST_TR - killed_at)
    assert new[0]["step"] == killed_at + 1  # resumed from the last complete checkpoint
    # Same losses, bit for bit, as the uninterrupted run from the restart on, and the same final state.
    ref = _losses(metrics(tgst_reference), "transformer")
    assert _losses(new, "transformer") == {s: ref[s] for s in range(killed_at + 1, TGST_TR + 1)}
    for stage, step in (("autoencoder", TGST_AE), ("transformer", TGST_TR)):
        assert_identical(params_at(work / "checkpoints" / stage, step),
                         params_at(tgst_reference / "checkpoints" / stage, step))


@pytest.mark.slow
def test_tgst_killed_during_a_save_resumes_from_the_previous_checkpoint(data, env, tgst_reference, tmp_path):
    caught = None
    for attempt in range(4):
        # Every step is saved; kill the moment a temporary checkpoint folder appears after a complete one.
        work = tmp_path / f"w{attempt}"
        ae_dir = work / "checkpoints" / "autoencoder"
        kill_when(_tgst(data, work, 100_000, 1, ckpt_every=1), env,
                  lambda: bool(complete_steps(ae_dir) and temporary_folders(ae_dir)))
        left = temporary_folders(ae_dir)
        if left:  # the kill interrupted a save: that step has no complete checkpoint
            caught = (left, complete_steps(ae_dir))
            break
    if caught is None:
        pytest.skip("4 kills all landed between two saves (no temporary folder left); nothing to test")
    left, steps = caught
    partial = int(re.match(r"(\d+)", left[0]).group(1))
    assert partial not in steps and steps[-1] == partial - 1, (left, steps)
    assert steps[-1] < TGST_AE
    r = _run(_tgst(data, work, TGST_AE, TGST_TR), env)
    assert f"autoencoder {TGST_AE} steps loss" in r.stdout, r.stdout
    assert not temporary_folders(ae_dir)  # orbax removed the incomplete save on restart
    for stage, step in (("autoencoder", TGST_AE), ("transformer", TGST_TR)):
        assert_identical(params_at(work / "checkpoints" / stage, step),
                         params_at(tgst_reference / "checkpoints" / stage, step))


# ----- ZeroEGGS ---------------------------------------------------------------------------------------------

def _zeggs(data, work, steps):
    return ["zeggs", "train", "--data", data, "--workdir", work, "--preset", "tiny", "--seed", SEED,
            "--steps", steps, "--ckpt-every", CKPT_EVERY, "--log-every", 1, "--devices", 1]


@pytest.mark.slow
def test_zeggs_killed_resumes_to_the_same_parameters(data, env, zeggs_workdir, tmp_path):
    ref = zeggs_workdir  # the uninterrupted run (same data, seed, steps and intervals)
    assert complete_steps(ref / "checkpoints" / "zeggs") == [CKPT_EVERY, ZEGGS_STEPS]

    work = tmp_path / "w"
    ckpt = work / "checkpoints" / "zeggs"
    # 500 steps: the run cannot end before it is killed at its first complete checkpoint.
    kill_when(_zeggs(data, work, 500), env, lambda: bool(complete_steps(ckpt)))
    killed_at = complete_steps(ckpt)[-1]
    assert CKPT_EVERY <= killed_at < ZEGGS_STEPS, complete_steps(ckpt)
    before = len(metrics(work))
    stats = (work / "pose_stats.json").read_bytes(), (work / "speech_stats.json").read_bytes()

    r = _run(_zeggs(data, work, ZEGGS_STEPS), env)
    assert f"resumed from {killed_at}" in r.stdout, r.stdout
    assert ((work / "pose_stats.json").read_bytes(), (work / "speech_stats.json").read_bytes()) == stats
    assert stats == ((ref / "pose_stats.json").read_bytes(), (ref / "speech_stats.json").read_bytes())
    new = metrics(work)[before:]
    assert [x["step"] for x in new] == list(range(killed_at + 1, ZEGGS_STEPS + 1))
    assert _losses(new, "zeggs") == {s: v for s, v in _losses(metrics(ref), "zeggs").items() if s > killed_at}
    assert_identical(params_at(ckpt, ZEGGS_STEPS), params_at(ref / "checkpoints" / "zeggs", ZEGGS_STEPS))


# ----- non-finite loss --------------------------------------------------------------------------------------

def _nan_problem(bad_step: int, where: str):
    """A linear regression whose loss (``where="loss"``) or only its gradient (``"grad"``, the loss stays
    finite at that step) becomes NaN from step ``bad_step`` (1-based) on."""
    params = {"w": jnp.ones((3,), jnp.float32)}
    state = TrainState.create(apply_fn=None, params=params, tx=optax.sgd(0.05))
    x = jnp.asarray(np.random.default_rng(0).normal(size=(8, 3)), jnp.float32)

    def step_fn(state, batch, key):
        bad = state.step + 1 >= bad_step

        def loss_fn(p):
            loss = jnp.mean((x @ p["w"] - batch) ** 2)
            return jnp.where(bad, jnp.nan, loss) if where == "loss" else loss

        loss, grads = jax.value_and_grad(loss_fn)(state.params)
        if where == "grad":
            grads = jax.tree_util.tree_map(lambda g: jnp.where(bad, jnp.nan, g), grads)
        return state.apply_gradients(grads=grads), {"loss": loss}

    return state, jax.jit(step_fn, donate_argnums=(0,)), lambda i: jnp.zeros((8,), jnp.float32)


@pytest.mark.parametrize("where,bad_step,log_every,message,kept", [
    ("loss", 5, 1, "train: non-finite loss at step 5; stopped", 4),
    ("loss", 5, 3, "train: non-finite loss at step 6; stopped", 4),  # found at the next log/checkpoint step
    # a NaN gradient at a checkpoint step: the loss of that step is still finite, the parameters are not
    ("grad", 6, 1, "train: non-finite parameters at step 6 (NaN/inf gradient); stopped", 4),
])
def test_non_finite_stops_and_keeps_the_last_good_checkpoint(tmp_path, key, where, bad_step, log_every,
                                                             message, kept):
    state, step_fn, batch_fn = _nan_problem(bad_step, where)
    ckpt = Checkpointer(tmp_path, kind="toy", config={"lr": 0.05}, max_to_keep=5)
    logger = MetricsLogger(tmp_path)
    with pytest.raises(TrainingError) as err:
        train_loop(state, step_fn, batch_fn, key=key, num_steps=10, checkpointer=ckpt, logger=logger,
                   log_every=log_every, ckpt_every=2, progress=False)
    text = str(err.value)
    assert text.startswith(message) and "\n" not in text, text
    assert f"the last good checkpoint (step {kept}) is kept (lower the learning rate" in text
    assert ckpt.latest_step() == kept
    restored = ckpt.restore(TrainState.create(apply_fn=None, params={"w": jnp.zeros((3,), jnp.float32)},
                                              tx=optax.sgd(0.05)))
    w = np.asarray(restored.params["w"])
    assert int(restored.step) == kept and np.all(np.isfinite(w)) and np.any(w != 1.0)  # real, finite steps
    lines = [json.loads(x) for x in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert lines and all(np.isfinite(r["loss"]) for r in lines)  # nothing non-finite was logged
    ckpt.close()


def test_non_finite_without_checkpoint_says_so(key):
    state, step_fn, batch_fn = _nan_problem(1, "loss")
    with pytest.raises(TrainingError, match=r"^train: non-finite loss at step 1; stopped, no checkpoint was "
                                            r"written \(lower the learning rate"):
        train_loop(state, step_fn, batch_fn, key=key, num_steps=3, log_every=1, progress=False)

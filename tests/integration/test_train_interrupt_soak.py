"""Nothing lost: SIGKILL at random moments, SIGTERM / SIGINT checkpoints, one writer per workdir.

* Soak: a small training (the shared :func:`jaxgest.runtime.training.train_loop` and a real
  :class:`~jaxgest.runtime.checkpoint.Checkpointer`, a toy problem in a subprocess) is SIGKILLed at 10 seeded random
  moments (mid-step, mid-save), resumed each time, and ends bit-identical to an uninterrupted run; then SIGTERMed
  at seeded random moments: each time it exits 143 with one line naming the step, the checkpoint is at that step
  and no step logged before the signal is lost, and the resumed run ends bit-identical too. A second signal
  during the save of the interrupt exits at once and leaves the previous checkpoint the latest.
* The real commands (``python -m jaxgest.cli``): ZeroEGGS SIGTERM and TGST SIGINT (transformer stage) save the
  interrupted step and exit 143 / 130 with one line; the TGST run, resumed (in-process, the same client as the
  subprocess), ends bit-identical to an uninterrupted run of the same length. A reader (``zeggs generate``)
  needs no lock while a training writes.
* One writer: a second ``train`` on a workdir in use exits 2 with one line naming the holder's PID; after
  ``kill -9`` of the holder a new ``train`` resumes with one warning line.
"""

from __future__ import annotations

import json
import os
import pathlib
import random
import signal
import subprocess
import sys
import tempfile
import time

import pytest

from conftest import NUM_DEVICES
from faults_testing import assert_identical, params_at, run
from tiny_models import CKPT_EVERY, TINY_SEED, train_tgst, train_zeggs

REPO = pathlib.Path(__file__).resolve().parents[2]
TMP_MARK = "orbax-checkpoint-tmp"

# A toy training through the shared loop: 64 parameters, Adam, a step that also waits 10 ms on the host (so a
# random moment can fall inside a step or a save), metrics every step, a checkpoint every 3 steps.
TOY = r"""
import sys, time
import jax, jax.numpy as jnp, optax
from jaxgest.runtime.errors import Interrupted
from jaxgest.runtime.training import Checkpointer, MetricsLogger, TrainState, train_loop

if __name__ == "__main__":
    work, steps, ckpt_every = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
state = TrainState.create(apply_fn=None, params={"w": jnp.zeros((64,), jnp.float32)}, tx=optax.adam(0.05))
target = jnp.linspace(-1.0, 1.0, 64, dtype=jnp.float32)

def step_fn(state, batch, key):
    noise = jax.random.normal(jax.random.fold_in(key, state.step), (64,)) * 0.01
    loss, g = jax.value_and_grad(lambda p: jnp.mean((p["w"] - target * batch + noise) ** 2))(state.params)
    return state.apply_gradients(grads=g), {"loss": loss}

def batch_fn(i):
    time.sleep(0.01)
    return jnp.float32(1.0 + 0.01 * i)

def run(work, steps, ckpt_every):
    with Checkpointer(work, kind="toy", config={"lr": 0.05}, max_to_keep=3) as ckpt:
        train_loop(ckpt.restore(state), jax.jit(step_fn, donate_argnums=(0,)), batch_fn, key=jax.random.key(0),
                   num_steps=steps, checkpointer=ckpt, logger=MetricsLogger(work), log_every=1,
                   ckpt_every=ckpt_every, progress=False)

if __name__ == "__main__":
    try:
        run(work, steps, ckpt_every)
    except Interrupted as e:  # what jaxgest.cli.main does
        print(f"jaxgest: {e}", file=sys.stderr)
        sys.exit(e.status)
"""

TOY_STEPS = 72


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    e = {k: v for k, v in os.environ.items() if not k.startswith(("XLA_", "JAX_PLATFORMS"))}
    e.setdefault("JAX_COMPILATION_CACHE_DIR", str(tmp_path_factory.mktemp("xla_cache")))
    e.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
    # the test process's CPU client (4 devices), so a subprocess's run compares bit for bit with in-process ones
    e.update(JAX_PLATFORMS="cpu", JAX_NUM_CPU_DEVICES=str(NUM_DEVICES), PYTHONPATH=str(REPO),
             PYTHONUNBUFFERED="1")
    return e


def start(argv, env, err):
    """Start ``argv`` with SIGINT not ignored: a test process started as a background job ignores SIGINT, and an
    ignored signal stays ignored across exec (a handled one is reset to the default)."""
    old = signal.getsignal(signal.SIGINT)
    if old is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=err, text=True)
    finally:  # Popen returns once the child has exec'd
        if old is signal.SIG_IGN:
            signal.signal(signal.SIGINT, old)


def toy(work, env, err, steps=TOY_STEPS, ckpt_every=3):
    return start([sys.executable, "-c", TOY, str(work), str(steps), str(ckpt_every)], env, err)


def cli(*args) -> list:
    return [sys.executable, "-m", "jaxgest.cli", *map(str, args)]


def metrics(work: pathlib.Path) -> list:
    p = work / "metrics.jsonl"
    return [json.loads(x) for x in p.read_text().splitlines() if x.strip()] if p.exists() else []


def complete_steps(ckpt_dir: pathlib.Path) -> list:
    if not ckpt_dir.is_dir():
        return []
    return sorted(int(p.name) for p in ckpt_dir.iterdir()
                  if p.name.isdigit() and (p / "_CHECKPOINT_METADATA").is_file())


def wait_for(proc, ready, err, timeout=600.0, poll=0.002):
    t0 = time.monotonic()
    while not ready():
        if proc.poll() is not None:
            err.seek(0)
            raise AssertionError(f"ended early (exit {proc.returncode}): {err.read()[-2000:]}")
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(poll)


def by_step(lines, stage=None) -> dict:
    """``{step: record}`` without the timing field; every repeated step (a killed run's logged but not
    checkpointed steps are logged again after the resume) must have logged the same values."""
    out = {}
    for r in lines:
        if stage is not None and r.get("stage") != stage:
            continue
        r = {k: v for k, v in r.items() if k != "steps_per_s"}
        assert out.setdefault(r["step"], r) == r, (out[r["step"]], r)
    return out


def interrupted_line(err_text: str, work, what: str, name: str) -> int:
    """The one stderr line of an interrupted run; returns the step it names."""
    lines = err_text.splitlines()
    assert len(lines) == 1, err_text[-3000:]
    head = f"jaxgest: {work}: {what} interrupted by {name} at step "
    assert lines[0].startswith(head), lines[0]
    step = int(lines[0][len(head):].split(";")[0])
    assert lines[0].endswith(f"; checkpoint saved at step {step} (run the same command to resume)"), lines[0]
    return step


@pytest.fixture(scope="module")
def toy_reference(tmp_path_factory):
    """The uninterrupted run, in this process (the subprocesses use the same CPU client, see ``env``)."""
    work = tmp_path_factory.mktemp("toy_reference")
    namespace = {"__name__": "toy"}
    exec(compile(TOY, "toy", "exec"), namespace)  # noqa: S102  (the toy script above)
    namespace["run"](work, TOY_STEPS, 3)
    return work


@pytest.mark.slow
def test_toy_training_killed_at_10_random_moments_ends_identical(env, toy_reference, tmp_path):
    rng = random.Random(42)
    work = tmp_path / "w"
    kills = []
    for _ in range(10):
        with tempfile.TemporaryFile("w+") as err:
            logged = len(metrics(work))
            p = toy(work, env, err)
            target = logged + rng.randint(1, 4)
            wait_for(p, lambda t=target: len(metrics(work)) >= t, err)
            time.sleep(rng.uniform(0.0, 0.03))  # anywhere in a step or a save
            p.send_signal(signal.SIGKILL)
            p.wait()
            assert p.returncode == -signal.SIGKILL
        kills.append(max(r["step"] for r in metrics(work)))
    assert kills[-1] < TOY_STEPS, kills  # every kill landed before the end
    with tempfile.TemporaryFile("w+") as err:
        p = toy(work, env, err)
        assert p.wait(timeout=600) == 0, err.seek(0) or err.read()[-3000:]
        err.seek(0)
        assert err.read() == ""
    assert_identical(params_at(work / "checkpoints", TOY_STEPS), params_at(toy_reference / "checkpoints", TOY_STEPS))
    got, ref = by_step(metrics(work)), by_step(metrics(toy_reference))
    assert got == ref


@pytest.mark.slow
def test_toy_training_sigterm_at_random_moments_loses_no_step(env, toy_reference, tmp_path):
    rng = random.Random(7)
    work = tmp_path / "w"
    for _ in range(2):
        with tempfile.TemporaryFile("w+") as err:
            before = len(metrics(work))
            p = toy(work, env, err, ckpt_every=1000)  # only the interrupt saves (and the end)
            target = before + rng.randint(1, 8)
            wait_for(p, lambda t=target: len(metrics(work)) >= t, err)
            time.sleep(rng.uniform(0.0, 0.03))
            seen = max(r["step"] for r in metrics(work))  # logged before the signal
            p.send_signal(signal.SIGTERM)
            assert p.wait(timeout=300) == 143
            err.seek(0)
            step = interrupted_line(err.read(), work, "train", "SIGTERM")
        assert step >= seen  # no step done before the signal is lost
        assert complete_steps(work / "checkpoints")[-1] == step < TOY_STEPS
        assert max(r["step"] for r in metrics(work)) == step  # the loop stopped right after it
    with tempfile.TemporaryFile("w+") as err:
        assert toy(work, env, err, ckpt_every=1000).wait(timeout=600) == 0
    assert_identical(params_at(work / "checkpoints", TOY_STEPS), params_at(toy_reference / "checkpoints", TOY_STEPS))
    assert by_step(metrics(work)) == by_step(metrics(toy_reference))


@pytest.mark.slow
def test_second_signal_during_the_interrupt_save_exits_at_once(env, tmp_path):
    ckdir = tmp_path / "w" / "checkpoints"
    for attempt in range(5):
        work = tmp_path / f"w{attempt}"
        ckdir = work / "checkpoints"
        with tempfile.TemporaryFile("w+") as err:
            p = toy(work, env, err, ckpt_every=4)
            wait_for(p, lambda c=ckdir, w=work: complete_steps(c) and len(metrics(w)) % 4 == 2, err)
            previous = complete_steps(ckdir)[-1]
            p.send_signal(signal.SIGTERM)  # the interrupt's save starts after this step
            t0 = time.monotonic()
            while p.poll() is None and not any(TMP_MARK in x.name for x in ckdir.iterdir()) \
                    and time.monotonic() - t0 < 60:
                time.sleep(0.0005)
            p.send_signal(signal.SIGTERM)
            status = p.wait(timeout=300)
            err.seek(0)
            text = err.read()
        if "again" in text:
            break
    else:
        pytest.skip("5 second signals all came after the interrupt's save had ended")
    assert status == 143
    lines = text.splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxgest: SIGTERM again during the checkpoint save of step "), text
    assert "stopped at once; the previous checkpoint is kept" in lines[0]
    assert complete_steps(ckdir)[-1] == previous  # the unfinished save did not replace it
    with tempfile.TemporaryFile("w+") as err:  # and the run resumes from it
        assert toy(work, env, err, steps=previous + 2).wait(timeout=600) == 0
    assert complete_steps(ckdir)[-1] == previous + 2


# ----- the real commands ------------------------------------------------------------------------------------

def _zeggs_cmd(data, work, steps, ckpt_every=CKPT_EVERY):
    return cli("zeggs", "train", "--data", data, "--workdir", work, "--preset", "tiny", "--seed", TINY_SEED,
               "--steps", steps, "--ckpt-every", ckpt_every, "--log-every", 1, "--devices", 1)


@pytest.mark.slow
def test_zeggs_second_writer_refused_reader_served_then_sigterm_saves_the_step(tiny, env, tmp_path, capsys):
    tiny_data = tiny["data"]
    work = tmp_path / "w"
    lock = work / ".jaxgest-train.lock"
    with tempfile.TemporaryFile("w+") as err:
        p = start(_zeggs_cmd(tiny_data, work, 100_000, ckpt_every=25), env, err)
        wait_for(p, lambda: lock.is_file() and lock.read_text().strip(), err)
        # a second writer: refused at once, one line naming the holder
        r = subprocess.run(_zeggs_cmd(tiny_data, work, 100_000), env=env, capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 2, r.stderr[-3000:]
        assert r.stderr.count("\n") == 1 and r.stderr.startswith(
            f"jaxgest: {work}: another training is writing to this workdir (PID {p.pid} on "), r.stderr
        # a reader needs no lock: it gets the newest complete checkpoint while the training writes
        wait_for(p, lambda: complete_steps(work / "checkpoints" / "zeggs"), err)
        rc, line, _ = run(["zeggs", "generate", "--workdir", work, "--audio", tiny["wav"], "--style", tiny["style"],
                           "--out", tmp_path / "g.bvh"], capsys)
        assert rc == 0 and line == "" and (tmp_path / "g.bvh").is_file(), line
        # SIGTERM
        assert p.poll() is None
        seen = max(r["step"] for r in metrics(work))
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=300) == 143
        err.seek(0)
        step = interrupted_line(err.read(), work, "zeggs", "SIGTERM")
    assert step >= seen and complete_steps(work / "checkpoints" / "zeggs")[-1] == step
    assert not lock.exists()  # released and removed: the next run has nothing to report
    # (that a resumed run ends bit-identical is checked by the toy soak and the TGST case below: one loop)
    assert max(r["step"] for r in metrics(work)) == step


@pytest.mark.slow
def test_tgst_sigint_in_the_transformer_stage_saves_the_step(tiny_data, env, tmp_path):
    work = tmp_path / "w"
    cmd = cli("tgst", "train", "--data", tiny_data, "--workdir", work, "--preset", "tiny", "--seed", TINY_SEED,
              "--ae-steps", 4, "--transformer-steps", 100_000, "--ckpt-every", CKPT_EVERY, "--log-every", 1,
              "--devices", 1)
    with tempfile.TemporaryFile("w+") as err:
        p = start(cmd, env, err)
        wait_for(p, lambda: any(r["stage"] == "transformer" for r in metrics(work)), err)
        seen = max(r["step"] for r in metrics(work) if r["stage"] == "transformer")
        p.send_signal(signal.SIGINT)
        assert p.wait(timeout=300) == 130
        err.seek(0)
        step = interrupted_line(err.read(), work, "tgst transformer", "SIGINT")
    assert step >= seen and complete_steps(work / "checkpoints" / "transformer")[-1] == step
    total = step + 2
    train_tgst(tiny_data, work, transformer_steps=total)
    ref = tmp_path / "ref"
    train_tgst(tiny_data, ref, transformer_steps=total)
    for stage, n in (("autoencoder", 4), ("transformer", total)):
        assert_identical(params_at(work / "checkpoints" / stage, n), params_at(ref / "checkpoints" / stage, n))
    assert by_step(metrics(work), "transformer") == by_step(metrics(ref), "transformer")


HOLD = r"""
import sys, time
from jaxgest.runtime.workdir_lock import exclusive_workdir
with exclusive_workdir(sys.argv[1]):
    print("held", flush=True)
    time.sleep(600)
"""


def test_lock_of_a_killed_writer_is_taken_over_with_one_warning(tiny_data, zeggs_workdir, env, tmp_path, capfd):
    """A writer killed with SIGKILL (here a process that only holds the lock of a copy of the session's
    ZeroEGGS workdir): the next ``train`` takes the workdir over with one warning line naming it, resumes from
    its checkpoint, and removes the lock file when it ends."""
    import shutil

    work = tmp_path / "w"
    shutil.copytree(zeggs_workdir, work)
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(work)], env=env, stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline() == "held\n"
    p.send_signal(signal.SIGKILL)
    p.wait()
    last = complete_steps(work / "checkpoints" / "zeggs")[-1]
    capfd.readouterr()
    summary = train_zeggs(tiny_data, work, steps=last + 1)
    err = capfd.readouterr().err
    assert summary["start_step"] == last
    assert err.count("\n") == 1 and err.startswith(
        f"jaxgest: warning: {work}: the training that held this workdir (PID {p.pid} on "), err
    assert "is gone without finishing (killed?); taking over from its last complete checkpoint" in err
    capfd.readouterr()
    train_zeggs(tiny_data, work, steps=last + 1)  # a clean end removed the lock: nothing to report
    assert capfd.readouterr().err == ""

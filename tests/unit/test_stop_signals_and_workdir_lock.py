"""In-process checks of the interrupt checkpoint (:func:`jaxgest.runtime.training.stop_on_signals` in
:func:`~jaxgest.runtime.training.train_loop`) and of the workdir writer lock (:mod:`jaxgest.runtime.workdir_lock`); the
subprocess scenarios are in tests/integration/test_train_interrupt_soak.py."""

from __future__ import annotations

import os
import signal
import socket

import pytest

from jaxgest.runtime.errors import Interrupted
from jaxgest.runtime.training import Checkpointer, stop_on_signals, train_loop
from jaxgest.runtime.workdir_lock import LOCK_NAME, WorkdirBusy, exclusive_workdir

from faults_testing import toy_problem


def test_stop_on_signals_records_the_first_and_restores_the_handlers(sigint_handled):
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with stop_on_signals() as request:
        assert request.signum is None
        os.kill(os.getpid(), signal.SIGTERM)  # handled at the next bytecode: the process goes on
        assert request.signum == signal.SIGTERM and request.name == "SIGTERM"
    assert {s: signal.getsignal(s) for s in before} == before


def test_an_ignored_signal_stays_ignored():
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with stop_on_signals() as request:
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGINT)
            assert request.signum is None
    finally:
        signal.signal(signal.SIGINT, old)


@pytest.fixture
def sigint_handled():
    """SIGINT with Python's default handler (a test process started as a background job ignores it)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


@pytest.mark.parametrize("signum,at", [(signal.SIGTERM, 5), (signal.SIGINT, 4)])
def test_train_loop_saves_the_interrupted_step(tmp_path, key, signum, at, sigint_handled):
    state, step_fn, batch_fn = toy_problem()

    def batches(i):
        if i == at - 1:  # during step `at`
            os.kill(os.getpid(), signum)
        return batch_fn(i)

    with Checkpointer(tmp_path, kind="toy", config={"lr": 0.05}) as ckpt:
        with pytest.raises(Interrupted) as err:
            train_loop(state, step_fn, batches, key=key, num_steps=100, checkpointer=ckpt, log_every=1,
                       ckpt_every=4, progress=False)
        assert ckpt.all_steps()[-1] == at
    name = signal.Signals(signum).name
    assert str(err.value) == (f"{tmp_path}: train interrupted by {name} at step {at}; checkpoint saved at step "
                              f"{at} (run the same command to resume)")
    assert err.value.status == 128 + signum


def test_train_loop_without_checkpointer_says_nothing_was_saved(key):
    state, step_fn, batch_fn = toy_problem()

    def batches(i):
        if i == 1:
            os.kill(os.getpid(), signal.SIGTERM)
        return batch_fn(i)

    with pytest.raises(Interrupted, match="^train interrupted by SIGTERM at step 2; no checkpoint is written"):
        train_loop(state, step_fn, batches, key=key, num_steps=10, log_every=1, progress=False)


def test_workdir_lock_one_writer(tmp_path):
    with exclusive_workdir(tmp_path, warn=pytest.fail):
        holder = (tmp_path / LOCK_NAME).read_text()
        assert holder.startswith(f"pid {os.getpid()} host {socket.gethostname()} since ")
        with pytest.raises(WorkdirBusy) as err, exclusive_workdir(tmp_path):
            pass
        assert str(err.value).startswith(f"{tmp_path}: another training is writing to this workdir (PID "
                                         f"{os.getpid()} on {socket.gethostname()}, started ")
        assert str(err.value).endswith("); wait for it to end, stop it, or use another --workdir")
    assert not (tmp_path / LOCK_NAME).exists()  # a clean end removes it
    with exclusive_workdir(tmp_path, warn=pytest.fail):  # and the next writer has nothing to report
        pass


def test_lock_left_by_a_killed_writer_is_taken_over_with_one_warning(tmp_path):
    (tmp_path / LOCK_NAME).write_text("pid 999999 host elsewhere since 2026-01-01T00:00:00Z\n")
    said = []
    with exclusive_workdir(tmp_path, warn=said.append):
        assert (tmp_path / LOCK_NAME).read_text().startswith(f"pid {os.getpid()} ")
    assert not (tmp_path / LOCK_NAME).exists()
    assert said == [f"{tmp_path}: the training that held this workdir (PID 999999 on elsewhere, started "
                    "2026-01-01T00:00:00Z) is gone without finishing (killed?); taking over from its last "
                    "complete checkpoint"]


def test_only_process_0_locks(tmp_path):
    with exclusive_workdir(tmp_path / "w", primary=False):
        assert not (tmp_path / "w").exists()


def test_an_error_inside_also_removes_the_lock(tmp_path):
    with pytest.raises(RuntimeError), exclusive_workdir(tmp_path, warn=pytest.fail):
        raise RuntimeError("a failed training")
    assert not (tmp_path / LOCK_NAME).exists()


def test_a_read_only_workdir_is_one_line(tmp_path, monkeypatch):
    import errno

    from jaxgest.runtime.errors import WriteError

    def refuse(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr("jaxgest.runtime.workdir_lock.os.open", refuse)
    with pytest.raises(WriteError, match=rf"^{tmp_path}/{LOCK_NAME}: cannot write \(Read-only file system\); "
                                         "training needs a writable workdir$"), exclusive_workdir(tmp_path):
        pass

"""Writes that cannot complete: checkpoint saves and metrics lines on a full disk or read-only folder, outputs
(BVH) on a full disk or into a read-only folder, training in a read-only workdir, an unhandled OSError, and
SIGKILL half-way through an output write. Each is one ``jaxgest: ...`` line (or WriteError), exit 2, no partial
or temporary file, and what was there before is unchanged. Full-disk and read-only faults are simulated with a
write that raises ENOSPC / EROFS (root ignores permission bits).
"""

from __future__ import annotations

import errno
import os
import pathlib
import shutil
import time

import pytest

from jaxgest.runtime import io
from jaxgest.runtime.errors import WriteError
from jaxgest.motion import bvh
from jaxgest.runtime.training import Checkpointer, MetricsLogger, train_loop

from faults_testing import NOISE, copy, infer, kill_when, run, snapshot, toy_problem


def _failing_json_save(monkeypatch, err=errno.ENOSPC):
    """orbax's meta item write fails as on a full disk (or read-only folder) after the arrays were written."""
    import orbax.checkpoint as ocp

    def fail(self, *a, **k):
        raise OSError(err, os.strerror(err))

    monkeypatch.setattr(ocp.JsonCheckpointHandler, "_save_fn", fail)


@pytest.mark.parametrize("err,why", [(errno.ENOSPC, "No space left on device"),
                                     (errno.EROFS, "Read-only file system")])
def test_checkpoint_save_that_cannot_complete(tmp_path, key, monkeypatch, capfd, err, why):
    s, step_fn, batch_fn = toy_problem()
    ck = Checkpointer(tmp_path, kind="toy", config={})
    state = train_loop(s, step_fn, batch_fn, key=key, num_steps=4, checkpointer=ck, ckpt_every=2, progress=False)
    before = snapshot(tmp_path / "checkpoints")
    capfd.readouterr()
    _failing_json_save(monkeypatch, err)
    with pytest.raises(WriteError) as e:
        train_loop(state, step_fn, batch_fn, key=key, num_steps=6, checkpointer=ck, ckpt_every=2, progress=False)
    assert str(e.value) == (f"{tmp_path}: toy checkpoint at step 6 could not be written ({why}); stopped, the last "
                            "good checkpoint (step 4) is kept")
    monkeypatch.undo()
    assert snapshot(tmp_path / "checkpoints") == before  # no partial folder, earlier steps untouched
    assert ck.all_steps() == [2, 4]
    ck.close()
    time.sleep(0.2)  # any orbax thread still running would log now
    out, err_text = capfd.readouterr()
    for bad in NOISE:
        assert bad not in err_text, err_text


def test_metrics_line_that_cannot_be_written_leaves_no_half_line(tmp_path, key, monkeypatch):
    s, step_fn, batch_fn = toy_problem()
    log = MetricsLogger(tmp_path)
    state = train_loop(s, step_fn, batch_fn, key=key, num_steps=2, logger=log, log_every=1, progress=False)
    before = (tmp_path / "metrics.jsonl").read_bytes()

    class HalfWriter:
        def __init__(self, path, mode):
            self.f = open(path, mode)

        def write(self, text):
            self.f.write(text[: len(text) // 2])
            self.f.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __enter__(self):
            return self

        def __exit__(self, *a):
            self.f.close()

    monkeypatch.setattr("jaxgest.runtime.training.open", HalfWriter, raising=False)
    with pytest.raises(WriteError, match=r"metrics.jsonl: cannot write \(No space left on device\); the existing "
                                         r"file is unchanged; stopped at step 3, no checkpoint was written"):
        train_loop(state, step_fn, batch_fn, key=key, num_steps=4, logger=log, log_every=1, progress=False)
    assert (tmp_path / "metrics.jsonl").read_bytes() == before


def _half_then_enospc(monkeypatch, module):
    """``open`` in ``module`` returns a file whose first write stores half the text, then fails (disk full)."""
    real = open

    class Half:
        def __init__(self, *a, **k):
            self.f = real(*a, **k)

        def write(self, text):
            self.f.write(text[: len(text) // 2])
            self.f.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name):
            return getattr(self.f, name)

        def __enter__(self):
            return self

        def __exit__(self, *a):
            self.f.close()

    monkeypatch.setattr(module, "open", Half, raising=False)


@pytest.mark.parametrize("existing", [False, True])
def test_output_on_a_full_disk(tiny, capsys, tmp_path, monkeypatch, existing):
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "o.bvh"
    if existing:
        out.write_text("previous output\n")
    before = snapshot(out_dir)
    _half_then_enospc(monkeypatch, bvh)
    rc, err, _ = run(infer(tiny, "tgst", tiny["tw"], out), capsys)
    kept = "the existing file is unchanged" if existing else "no file was written"
    assert rc == 2 and err == f"jaxgest: {out}: cannot write (No space left on device); {kept}", err
    assert snapshot(out_dir) == before  # no partial output, no temporary file


def test_output_into_a_read_only_folder(tiny, capsys, tmp_path, monkeypatch):
    out = tmp_path / "o.bvh"

    def read_only(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(tmp_path))

    monkeypatch.setattr(io.tempfile, "mkstemp", read_only)
    rc, err, _ = run(infer(tiny, "zeggs", tiny["zw"], out), capsys)
    assert rc == 2 and err == f"jaxgest: {out}: cannot write (Read-only file system); no file was written", err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_training_in_a_read_only_workdir(tiny, capsys, tmp_path, monkeypatch, model):
    work = copy(tiny, model, tmp_path)
    before = snapshot(work)

    def read_only(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(work))

    monkeypatch.setattr(io.tempfile, "mkstemp", read_only)
    steps = ["--ae-steps", 6, "--transformer-steps", 6] if model == "tgst" else ["--steps", 6]
    rc, err, _ = run([model, "train", "--data", tiny["data"], "--workdir", work, *steps], capsys)
    assert rc == 2 and err.startswith(f"jaxgest: {work}/") and "cannot write (Read-only file system)" in err, err
    assert snapshot(work) == before


def test_unhandled_os_error_is_one_line(tiny, capsys, tmp_path, monkeypatch):
    """A folder that cannot be created (read-only parent): the CLI's last resort for OSError."""
    target = tmp_path / "new"
    real = pathlib.Path.mkdir

    def mkdir(self, *a, **k):
        if self == target:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        return real(self, *a, **k)

    monkeypatch.setattr(pathlib.Path, "mkdir", mkdir)
    rc, err, _ = run(["zeggs", "train", "--data", tiny["data"], "--workdir", target, "--steps", 1], capsys)
    assert rc == 2 and err == f"jaxgest: {target}: Read-only file system", err


def test_sigkill_during_an_output_write(tiny, capsys, tmp_path):
    """Killed half-way through writing a BVH over an existing output: the output is the old one; the hidden
    temporary file left by the dead process is removed by the next write to that path."""
    out = tmp_path / "o.bvh"
    shutil.copy(tiny["content"], out)
    old = out.read_bytes()
    marker = tmp_path / "writing"
    code = f"""
import pathlib, time
from jaxgest.runtime.io import atomic_output
with atomic_output({str(out)!r}) as tmp:
    with open(tmp, "w") as f:
        f.write("HIERARCHY\\nROOT Hips\\n")  # the first part of a file
        f.flush()
        pathlib.Path({str(marker)!r}).touch()
        time.sleep(600)
"""
    kill_when(code, marker)
    assert out.read_bytes() == old  # never a partial output at the user's path
    left = [p for p in tmp_path.iterdir() if p.name.startswith(".o.")]
    assert len(left) == 1 and io.TMP_MARK in left[0].name  # the dead writer's temporary file
    rc, err, _ = run(infer(tiny, "tgst", tiny["tw"], out), capsys)
    assert rc == 0 and err == "", err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.bvh", "writing"]
    assert bvh.load(out).num_frames == bvh.load(tiny["content"]).num_frames

"""Faults beyond bad input: unreadable checkpoints, writes that cannot complete, workdirs of another format, and
SIGKILL in the middle of a write.

Every case runs the command line in-process (``jaxgest.cli.main``) on tiny trained workdirs (TGST 4+4 steps,
ZeroEGGS 4 steps, checkpoints every 2 steps, so each stage keeps steps 2 and 4) and checks: the exit status;
stderr is exactly one ``jaxgest: ...`` line (an error, or a warning when the command fell back and succeeded)
with no traceback, no absl chatter and no asyncio "Event loop is closed"; no partial or temporary file is left;
and what was there before (earlier checkpoints, an existing output) is unchanged. Full-disk and read-only
faults are simulated with a write that raises ENOSPC / EROFS (root ignores permission bits); the two SIGKILL
cases and one end-to-end process run use subprocesses.
"""

from __future__ import annotations

import errno
import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxgest import cli, io
from jaxgest.errors import CheckpointError, WriteError
from jaxgest.motion import bvh
from jaxgest.motion.synthetic import write_dataset
from jaxgest.training import (FORMAT_VERSION, Checkpointer, MetricsLogger, TrainState, strict_checkpoints,
                              train_loop)

REPO = pathlib.Path(__file__).resolve().parents[1]
NOISE = ("Traceback", "Event loop is closed", "absl", "WARNING:", "ERROR:")


@pytest.fixture(scope="module")
def ctx(tmp_path_factory):
    """Synthetic data and tiny trained TGST / ZeroEGGS workdirs with two checkpoints per stage."""
    from jaxgest.tgst.train import train as tgst_train
    from jaxgest.zeggs.train import train as zeggs_train

    root = tmp_path_factory.mktemp("faults")
    data = root / "data"
    write_dataset(data, clips=4, seconds=3, progress=False)
    tw, zw = root / "tgst", root / "zeggs"
    tgst_train(data, tw, preset="tiny", ae_steps=4, transformer_steps=4, progress=False, log_every=1,
               ckpt_every=2)
    zeggs_train(data, zw, preset="tiny", steps=4, progress=False, log_every=1, ckpt_every=2)
    for w, stages in ((tw, ("autoencoder", "transformer")), (zw, ("zeggs",))):
        for s in stages:
            assert sorted(p.name for p in (w / "checkpoints" / s).iterdir()) == ["2", "4"]
    return {"root": root, "data": data, "tw": tw, "zw": zw, "content": data / "greeting_neutral_0.bvh",
            "style": data / "greeting_sad_0.bvh", "wav": data / "greeting_neutral_0.wav"}


def snapshot(folder: pathlib.Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def run(argv, capsys) -> tuple[int, str, str]:
    """``(status, the one stderr line, stdout)``; fails on more than one line or any traceback/noise."""
    capsys.readouterr()
    rc = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    for bad in NOISE:
        assert bad not in err, err
    assert err.count("\n") <= 1 and "\r" not in err, repr(err)
    return rc, err.rstrip("\n"), out


def copy(ctx, model, tmp_path) -> pathlib.Path:
    work = tmp_path / model
    shutil.copytree(ctx["tw" if model == "tgst" else "zw"], work)
    return work


def infer(ctx, model, work, out, strict=False) -> list:
    argv = (["tgst", "transfer", "--workdir", work, "--content", ctx["content"], "--style", ctx["style"]]
            if model == "tgst" else
            ["zeggs", "generate", "--workdir", work, "--audio", ctx["wav"], "--style", ctx["style"]])
    return argv + ["--out", out] + (["--strict"] if strict else [])


STAGE = {"tgst": "transformer", "zeggs": "zeggs"}


# ----- corrupting one checkpoint step ------------------------------------------------------------------------

def _data_files(step_dir):
    return sorted((step_dir / "state").rglob("d/*"), key=lambda p: (-p.stat().st_size, p.name))


def truncate_data(step_dir):  # a crash during a copy, a full disk
    for f in _data_files(step_dir):
        os.truncate(f, min(100, f.stat().st_size // 2))


def flip_bytes(step_dir):  # bit rot that still decodes: caught by the checksum in the meta item
    f = _data_files(step_dir)[0]
    b = bytearray(f.read_bytes())
    for i in range(len(b) // 3, len(b) // 3 + 32):
        b[i] ^= 0xFF
    f.write_bytes(bytes(b))


def missing_state(step_dir):
    shutil.rmtree(step_dir / "state")


def garbage_meta(step_dir):
    (step_dir / "meta" / "metadata").write_text("{not json")


CORRUPTIONS = {"truncated": (truncate_data, "a data file is truncated or corrupted"),
               "flipped": (flip_bytes, "its arrays do not match the checksum saved with them"),
               "missing": (missing_state, "a file is missing"),
               "garbage_meta": (garbage_meta, "its metadata is not valid JSON")}


# every corruption on TGST; on ZeroEGGS the two array-level ones (the rest is the same code path)
@pytest.mark.parametrize("model,how", [("tgst", h) for h in CORRUPTIONS] + [("zeggs", "truncated"),
                                                                             ("zeggs", "flipped")])
def test_inference_falls_back_to_the_newest_readable_checkpoint(ctx, capsys, tmp_path, model, how):
    work = copy(ctx, model, tmp_path)
    corrupt, reason = CORRUPTIONS[how]
    corrupt(work / "checkpoints" / STAGE[model] / "4")
    before = snapshot(work)
    out = tmp_path / "out" / "o.bvh"
    out.parent.mkdir()
    rc, err, _ = run(infer(ctx, model, work, out), capsys)
    assert rc == 0, err
    assert err == (f"jaxgest: warning: {work}: {STAGE[model]} checkpoint at step 4 is unreadable ({reason}); "
                   "using step 2 instead (nothing was changed; --strict refuses)")
    assert bvh.load(out).num_frames > 0
    assert snapshot(work) == before  # inference moves and deletes nothing

    # --strict (a fresh copy: a loaded model is cached per workdir within a process)
    strict = copy(ctx, model, tmp_path / "strict")
    corrupt(strict / "checkpoints" / STAGE[model] / "4")
    out2 = tmp_path / "out" / "strict.bvh"
    rc, err, _ = run(infer(ctx, model, strict, out2, strict=True), capsys)
    assert rc == 2 and err == (f"jaxgest: {strict}: {STAGE[model]} checkpoint at step 4 is unreadable "
                               f"({reason}); --strict: not falling back to step 2"), err
    assert not out2.exists() and sorted(p.name for p in out.parent.iterdir()) == ["o.bvh"]


def test_every_checkpoint_unreadable_is_one_line(ctx, capsys, tmp_path):
    work = copy(ctx, "tgst", tmp_path)
    for step in ("2", "4"):
        truncate_data(work / "checkpoints" / "autoencoder" / step)
    out = tmp_path / "o.bvh"
    rc, err, _ = run(infer(ctx, "tgst", work, out), capsys)
    assert rc == 2 and err == (
        f"jaxgest: {work}: no readable autoencoder checkpoint (step 4: a data file is truncated or corrupted; "
        "step 2: a data file is truncated or corrupted); restore autoencoder/ from a backup, or move it aside "
        "to train from scratch"), err
    assert not out.exists()


def test_training_resumes_from_the_previous_checkpoint_and_ends_identical(ctx, capsys, tmp_path):
    """Latest transformer checkpoint (step 4) corrupt: training resumes from step 2 and ends, at step 6, with
    the parameters and losses of an uninterrupted run (the fixture's run continued from 4 to 6)."""
    from test_resume_kill import assert_identical, params_at

    def train(work):
        return ["tgst", "train", "--data", ctx["data"], "--workdir", work, "--ae-steps", 4,
                "--transformer-steps", 6, "--ckpt-every", 2, "--log-every", 1]

    ref = copy(ctx, "tgst", tmp_path / "ref")
    rc, err, out = run(train(ref), capsys)
    assert rc == 0 and err == "", err

    work = copy(ctx, "tgst", tmp_path)
    bad = work / "checkpoints" / "transformer" / "4"
    truncate_data(bad)
    bad_files = snapshot(bad)
    lines_before = len((work / "metrics.jsonl").read_text().splitlines())
    rc, err, out = run(train(work), capsys)
    assert rc == 0, err
    assert err == (f"jaxgest: warning: {work}: transformer checkpoint at step 4 is unreadable (a data file is "
                   "truncated or corrupted); resuming from step 2 (moved to "
                   "checkpoints/transformer.unreadable-step-4; nothing was deleted)")
    assert "transformer 6 steps loss" in out and "(from step 2)" in out, out
    assert snapshot(work / "checkpoints" / "transformer.unreadable-step-4") == bad_files  # kept, unchanged
    new = [json.loads(x) for x in (work / "metrics.jsonl").read_text().splitlines()[lines_before:]]
    assert [r["step"] for r in new] == [3, 4, 5, 6]
    ref_lines = {r["step"]: r for r in map(json.loads, (ref / "metrics.jsonl").read_text().splitlines())
                 if r["stage"] == "transformer"}
    for r in new:
        assert {k: v for k, v in r.items() if k != "steps_per_s"} == {
            k: v for k, v in ref_lines[r["step"]].items() if k != "steps_per_s"}
    for stage, step in (("autoencoder", 4), ("transformer", 6)):
        assert_identical(params_at(work / "checkpoints" / stage, step), params_at(ref / "checkpoints" / stage, step))

    strict = copy(ctx, "tgst", tmp_path / "strict")
    truncate_data(strict / "checkpoints" / "transformer" / "4")
    before = snapshot(strict)
    rc, err, _ = run(train(strict) + ["--strict"], capsys)
    assert rc == 2 and "transformer checkpoint at step 4 is unreadable" in err and "--strict" in err, err
    assert snapshot(strict) == before


# ----- toy model: resume after a corrupt latest checkpoint, and saves that fail ------------------------------

def _toy():
    params = {"w": jnp.zeros((64,), jnp.float32)}
    state = TrainState.create(apply_fn=None, params=params, tx=optax.adam(0.05))
    target = jnp.linspace(-1.0, 1.0, 64, dtype=jnp.float32)

    def step_fn(state, batch, key):
        noise = jax.random.normal(jax.random.fold_in(key, state.step), (64,)) * 0.01
        loss, g = jax.value_and_grad(lambda p: jnp.mean((p["w"] - target * batch + noise) ** 2))(state.params)
        return state.apply_gradients(grads=g), {"loss": loss}

    return state, jax.jit(step_fn, donate_argnums=(0,)), lambda i: jnp.float32(1.0 + 0.01 * i)


def test_toy_resume_after_corrupt_latest_equals_uninterrupted(tmp_path, key, capsys):
    s, step_fn, batch_fn = _toy()
    full = train_loop(s, step_fn, batch_fn, key=key, num_steps=12, progress=False)
    ck = Checkpointer(tmp_path, kind="toy", config={})
    train_loop(_toy()[0], step_fn, batch_fn, key=key, num_steps=8, checkpointer=ck, ckpt_every=4,
               progress=False)
    ck.close()
    truncate_data(tmp_path / "checkpoints" / "8")
    capsys.readouterr()
    ck = Checkpointer(tmp_path, kind="toy", config={})
    resumed = ck.restore(_toy()[0])
    assert int(resumed.step) == 4 and ck.restored_step == 4
    resumed = train_loop(resumed, step_fn, batch_fn, key=key, num_steps=12, checkpointer=ck, ckpt_every=4,
                         progress=False)
    ck.close()
    err = capsys.readouterr().err
    assert err == (f"jaxgest: warning: {tmp_path}: toy checkpoint at step 8 is unreadable (a data file is truncated "
                   "or corrupted); resuming from step 4 (moved to checkpoints.unreadable-step-8; nothing was "
                   "deleted)\n"), err
    np.testing.assert_array_equal(np.asarray(resumed.params["w"]), np.asarray(full.params["w"]))
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir()) == ["12", "8"]
    assert (tmp_path / "checkpoints.unreadable-step-8").is_dir()


def test_strict_refuses_and_explicit_step_never_falls_back(tmp_path, key):
    s, step_fn, batch_fn = _toy()
    ck = Checkpointer(tmp_path, kind="toy", config={})
    train_loop(s, step_fn, batch_fn, key=key, num_steps=4, checkpointer=ck, ckpt_every=2, progress=False)
    ck.close()
    missing_state(tmp_path / "checkpoints" / "4")
    ro = Checkpointer(tmp_path, kind="toy", config={}, read_only=True)
    with strict_checkpoints(), pytest.raises(CheckpointError, match=r"step 4 is unreadable \(a file is missing\); "
                                                                    r"--strict: not falling back to step 2"):
        ro.restore(_toy()[0])
    with pytest.raises(CheckpointError, match=r"step 4 is unreadable .*restore checkpoints/ from a backup"):
        ro.restore(_toy()[0], step=4)
    assert int(ro.restore(_toy()[0], step=2).step) == 2
    ro.close()
    assert (tmp_path / "checkpoints" / "4").is_dir()  # nothing moved in read-only use


def _failing_json_save(monkeypatch, err=errno.ENOSPC):
    """orbax's meta item write fails as on a full disk (or read-only folder) after the arrays were written."""
    import orbax.checkpoint as ocp

    def fail(self, *a, **k):
        raise OSError(err, os.strerror(err))

    monkeypatch.setattr(ocp.JsonCheckpointHandler, "_save_fn", fail)


@pytest.mark.parametrize("err,why", [(errno.ENOSPC, "No space left on device"),
                                     (errno.EROFS, "Read-only file system")])
def test_checkpoint_save_that_cannot_complete(tmp_path, key, monkeypatch, capfd, err, why):
    s, step_fn, batch_fn = _toy()
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
    s, step_fn, batch_fn = _toy()
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

    monkeypatch.setattr("jaxgest.training.open", HalfWriter, raising=False)
    with pytest.raises(WriteError, match=r"metrics.jsonl: cannot write \(No space left on device\); the existing "
                                         r"file is unchanged; stopped at step 3, no checkpoint was written"):
        train_loop(state, step_fn, batch_fn, key=key, num_steps=4, logger=log, log_every=1, progress=False)
    assert (tmp_path / "metrics.jsonl").read_bytes() == before


# ----- outputs that cannot be written ----------------------------------------------------------------------

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
def test_output_on_a_full_disk(ctx, capsys, tmp_path, monkeypatch, existing):
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "o.bvh"
    if existing:
        out.write_text("previous output\n")
    before = snapshot(out_dir)
    _half_then_enospc(monkeypatch, bvh)
    rc, err, _ = run(infer(ctx, "tgst", ctx["tw"], out), capsys)
    kept = "the existing file is unchanged" if existing else "no file was written"
    assert rc == 2 and err == f"jaxgest: {out}: cannot write (No space left on device); {kept}", err
    assert snapshot(out_dir) == before  # no partial output, no temporary file


def test_output_into_a_read_only_folder(ctx, capsys, tmp_path, monkeypatch):
    out = tmp_path / "o.bvh"

    def read_only(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(tmp_path))

    monkeypatch.setattr(io.tempfile, "mkstemp", read_only)
    rc, err, _ = run(infer(ctx, "zeggs", ctx["zw"], out), capsys)
    assert rc == 2 and err == f"jaxgest: {out}: cannot write (Read-only file system); no file was written", err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_training_in_a_read_only_workdir(ctx, capsys, tmp_path, monkeypatch, model):
    work = copy(ctx, model, tmp_path)
    before = snapshot(work)

    def read_only(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(work))

    monkeypatch.setattr(io.tempfile, "mkstemp", read_only)
    steps = ["--ae-steps", 6, "--transformer-steps", 6] if model == "tgst" else ["--steps", 6]
    rc, err, _ = run([model, "train", "--data", ctx["data"], "--workdir", work, *steps], capsys)
    assert rc == 2 and err.startswith(f"jaxgest: {work}/") and "cannot write (Read-only file system)" in err, err
    assert snapshot(work) == before


def test_unhandled_os_error_is_one_line(ctx, capsys, tmp_path, monkeypatch):
    """A folder that cannot be created (read-only parent): the CLI's last resort for OSError."""
    target = tmp_path / "new"
    real = pathlib.Path.mkdir

    def mkdir(self, *a, **k):
        if self == target:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        return real(self, *a, **k)

    monkeypatch.setattr(pathlib.Path, "mkdir", mkdir)
    rc, err, _ = run(["zeggs", "train", "--data", ctx["data"], "--workdir", target, "--steps", 1], capsys)
    assert rc == 2 and err == f"jaxgest: {target}: Read-only file system", err


# ----- format and version drift ----------------------------------------------------------------------------

def _edit_config(work, fn):
    path = work / "config.json"
    d = json.loads(path.read_text())
    fn(d)
    path.write_text(json.dumps(d))


def _edit_meta(work, stage, fn):
    for step in ("2", "4"):
        path = work / "checkpoints" / stage / step / "meta" / "metadata"
        d = json.loads(path.read_text())
        fn(d)
        path.write_text(json.dumps(d))


def test_new_workdirs_are_stamped(ctx):
    for w in (ctx["tw"], ctx["zw"]):
        assert json.loads((w / "config.json").read_text())["format_version"] == FORMAT_VERSION == 1


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_workdir_without_stamp_reads_as_version_1(ctx, capsys, tmp_path, model):
    work = copy(ctx, model, tmp_path)
    _edit_config(work, lambda d: d.pop("format_version"))
    _edit_meta(work, STAGE[model], lambda d: d.pop("format_version"))
    rc, err, _ = run(infer(ctx, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 0 and err == "", err


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
@pytest.mark.parametrize("command", ["infer", "train"])
def test_workdir_from_a_newer_version(ctx, capsys, tmp_path, model, command):
    work = copy(ctx, model, tmp_path)
    _edit_config(work, lambda d: d.update(format_version=FORMAT_VERSION + 1))
    before = snapshot(work)
    argv = (infer(ctx, model, work, tmp_path / "o.bvh") if command == "infer" else
            [model, "train", "--data", ctx["data"], "--workdir", work])
    rc, err, _ = run(argv, capsys)
    assert rc == 2 and err == (f"jaxgest: {work}: written by a newer jaxgest (workdir format 2, this version "
                               "reads up to 1); upgrade jaxgest, or retrain into a new --workdir"), err
    assert snapshot(work) == before


def test_checkpoint_from_a_newer_version(ctx, capsys, tmp_path):
    work = copy(ctx, "zeggs", tmp_path)
    _edit_meta(work, "zeggs", lambda d: d.update(format_version=FORMAT_VERSION + 1))
    rc, err, _ = run(infer(ctx, "zeggs", work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and "checkpoint written by a newer jaxgest (format version 2; this one reads up to 1)" in err


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_unknown_model_kind(ctx, capsys, tmp_path, model):
    work = copy(ctx, model, tmp_path)
    _edit_config(work, lambda d: d.update(model="gesturenet"))
    rc, err, _ = run(infer(ctx, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and err == (f"jaxgest: {work}: config.json names 'gesturenet' (this jaxgest knows tgst, zeggs): "
                               "an older layout or not a jaxgest workdir; retrain into a new --workdir"), err


@pytest.mark.parametrize("model,field", [("tgst", "edge_frames")])
def test_older_layout_without_a_current_field(ctx, capsys, tmp_path, model, field):
    """A workdir written before ``field`` (of the model config) existed (absent from config.json and from the
    checkpoints)."""
    work = copy(ctx, model, tmp_path)
    _edit_config(work, lambda d: (d["config"]["model"] if model == "tgst" else d["config"]).pop(field))
    for stage in (("autoencoder", "transformer") if model == "tgst" else ("zeggs",)):
        _edit_meta(work, stage, lambda d: d["config"].pop(field, None))
    rc, err, _ = run(infer(ctx, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and "checkpoint from an older version of jaxgest (config without" in err and field in err, err
    assert err.endswith("retrain into a new --workdir with this version (checkpoints are not converted)"), err


def test_older_zeggs_layout_without_a_current_field_still_generates(ctx, capsys, tmp_path):
    """ZeroEGGS reads its checkpoint against config.json as stored: a workdir written before a (training-only)
    field existed still generates, with no output on stderr (fields that change inference have legacy values in
    jaxgest.zeggs.config.LEGACY_DEFAULTS, tested in test_zeggs_model/test_zeggs_api)."""
    work = copy(ctx, "zeggs", tmp_path)
    _edit_config(work, lambda d: d["config"]["train"].pop("style_window_max"))
    _edit_meta(work, "zeggs", lambda d: d["config"].pop("style_window_max", None))
    rc, err, _ = run(infer(ctx, "zeggs", work, tmp_path / "o.bvh"), capsys)
    assert rc == 0 and err == "", err
    assert (tmp_path / "o.bvh").is_file()


def test_config_with_an_unknown_field(ctx, capsys, tmp_path):
    work = copy(ctx, "zeggs", tmp_path)
    _edit_config(work, lambda d: d["config"].update(future_knob=3))
    rc, err, _ = run(infer(ctx, "zeggs", work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and err.startswith(f"jaxgest: {work}/config.json: config from another version of jaxgest"), err
    assert "future_knob" in err and err.endswith("retrain into a new --workdir")


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_truncated_config_json(ctx, capsys, tmp_path, model):
    work = copy(ctx, model, tmp_path)
    text = (work / "config.json").read_text()
    (work / "config.json").write_text(text[: len(text) // 2])
    rc, err, _ = run(infer(ctx, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and err == (f"jaxgest: {work}/config.json: unreadable (not valid JSON: truncated or "
                               "corrupted?); restore it from a backup or retrain into a new --workdir"), err
    # training rewrites config.json (the checkpoints carry their own config): nothing to train, file repaired
    steps = ["--ae-steps", 4, "--transformer-steps", 4] if model == "tgst" else ["--steps", 4]
    rc, err, out = run([model, "train", "--data", ctx["data"], "--workdir", work, *steps], capsys)
    assert rc == 0 and err == "" and "nothing to do" in out, (err, out)
    assert json.loads((work / "config.json").read_text())["format_version"] == FORMAT_VERSION


# ----- SIGKILL in the middle of a write (subprocesses) -----------------------------------------------------

def _env():
    e = {k: v for k, v in os.environ.items() if not k.startswith(("XLA_", "JAX_PLATFORMS"))}
    e.update(JAX_PLATFORMS="cpu", PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    return e


def _kill_when(code: str, marker: pathlib.Path, timeout=300.0):
    """Run ``python -c code``; SIGKILL it as soon as ``marker`` exists."""
    proc = subprocess.Popen([sys.executable, "-c", code], env=_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    try:
        while not marker.exists():
            assert proc.poll() is None, f"ended before the kill: {proc.stderr.read()[-2000:]}"
            assert time.monotonic() - t0 < timeout, "the write never started"
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL


def test_sigkill_during_an_output_write(ctx, capsys, tmp_path):
    """Killed half-way through writing a BVH over an existing output: the output is the old one; the hidden
    temporary file left by the dead process is removed by the next write to that path."""
    out = tmp_path / "o.bvh"
    shutil.copy(ctx["content"], out)
    old = out.read_bytes()
    marker = tmp_path / "writing"
    code = f"""
import pathlib, time
from jaxgest.io import atomic_output
with atomic_output({str(out)!r}) as tmp:
    with open(tmp, "w") as f:
        f.write("HIERARCHY\\nROOT Hips\\n")  # the first part of a file
        f.flush()
        pathlib.Path({str(marker)!r}).touch()
        time.sleep(600)
"""
    _kill_when(code, marker)
    assert out.read_bytes() == old  # never a partial output at the user's path
    left = [p for p in tmp_path.iterdir() if p.name.startswith(".o.")]
    assert len(left) == 1 and io.TMP_MARK in left[0].name  # the dead writer's temporary file
    rc, err, _ = run(infer(ctx, "tgst", ctx["tw"], out), capsys)
    assert rc == 0 and err == "", err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.bvh", "writing"]
    assert bvh.load(out).num_frames == bvh.load(ctx["content"]).num_frames


def test_sigkill_during_a_checkpoint_save(tmp_path, key):
    """Killed inside a save (the arrays written, the meta item not yet): the next run of the workdir sees the
    previous checkpoint as the latest, removes the temporary folder and resumes from it."""
    marker = tmp_path / "saving"
    code = f"""
import pathlib, time, jax, jax.numpy as jnp, optax
import orbax.checkpoint as ocp
from jaxgest.training import Checkpointer, TrainState
state = TrainState.create(apply_fn=None, params={{"w": jnp.arange(64, dtype=jnp.float32)}}, tx=optax.adam(0.1))
ck = Checkpointer({str(tmp_path)!r}, kind="toy", config={{}})
ck.save(state.replace(step=jnp.int32(2)))
real = ocp.JsonCheckpointHandler._save_fn
def hang(self, *a, **k):
    pathlib.Path({str(marker)!r}).touch()
    time.sleep(600)
ocp.JsonCheckpointHandler._save_fn = hang
ck.save(state.replace(step=jnp.int32(4)))
"""
    _kill_when(code, marker)
    ckdir = tmp_path / "checkpoints"
    assert [p.name for p in ckdir.iterdir() if "orbax-checkpoint-tmp" in p.name]  # the interrupted save
    ro = Checkpointer(tmp_path, kind="toy", config={}, read_only=True)  # inference: sees step 2 only
    assert ro.all_steps() == [2]
    ro.close()
    s, _, _ = _toy()
    s = s.replace(params={"w": jnp.zeros((64,), jnp.float32)})
    ck = Checkpointer(tmp_path, kind="toy", config={})
    restored = ck.restore(s)
    assert int(restored.step) == 2
    np.testing.assert_array_equal(np.asarray(restored.params["w"]), np.arange(64, dtype=np.float32))
    ck.close()
    assert sorted(p.name for p in ckdir.iterdir()) == ["2"]  # orbax removed the unfinished save


@pytest.mark.parametrize("strict", [True, pytest.param(False, marks=pytest.mark.slow)])
def test_corrupt_checkpoint_in_a_real_process_is_one_clean_line(ctx, tmp_path, strict):
    """The original report: a truncated transformer checkpoint and ``tgst transfer`` in a fresh process --
    --strict: exit 2, one line; without: exit 0 with one warning line. No traceback, no asyncio "Event loop
    is closed" from orbax's unfinished reads at exit (the slow case compiles the transfer in the subprocess)."""
    work = copy(ctx, "tgst", tmp_path)
    truncate_data(work / "checkpoints" / "transformer" / "4")
    env = _env()
    env.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
    for status in ([2] if strict else [0]):
        out = tmp_path / "o.bvh"
        r = subprocess.run([sys.executable, "-m", "jaxgest.cli", *map(str, infer(ctx, "tgst", work, out, strict))],
                           env=env, capture_output=True, text=True, timeout=600)
        assert r.returncode == status, r.stderr[-3000:]
        lines = r.stderr.splitlines()
        assert len(lines) == 1 and "transformer checkpoint at step 4 is unreadable" in lines[0], r.stderr[-3000:]
        assert out.exists() == (not strict)

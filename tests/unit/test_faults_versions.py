"""Workdirs of another format: missing or newer ``format_version`` stamps, unknown model kinds, configs from
an older or newer layout, and a truncated config.json -- one line naming the workdir and what to do, exit 2,
nothing changed (or, where documented, the workdir still works). In-process CLI on copies of the session's
tiny workdirs.
"""

from __future__ import annotations

import json

import pytest

from jaxgest.motion import bvh
from jaxgest.runtime.training import FORMAT_VERSION

from faults_testing import STAGE, copy, infer, run, snapshot


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


def test_new_workdirs_are_stamped(tiny):
    for w in (tiny["tw"], tiny["zw"]):
        assert json.loads((w / "config.json").read_text())["format_version"] == FORMAT_VERSION == 1


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_workdir_without_stamp_reads_as_version_1(tiny, capsys, tmp_path, model):
    work = copy(tiny, model, tmp_path)
    _edit_config(work, lambda d: d.pop("format_version"))
    _edit_meta(work, STAGE[model], lambda d: d.pop("format_version"))
    rc, err, _ = run(infer(tiny, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 0 and err == "", err


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
@pytest.mark.parametrize("command", ["infer", "train"])
def test_workdir_from_a_newer_version(tiny, capsys, tmp_path, model, command):
    work = copy(tiny, model, tmp_path)
    _edit_config(work, lambda d: d.update(format_version=FORMAT_VERSION + 1))
    before = snapshot(work)
    argv = (infer(tiny, model, work, tmp_path / "o.bvh") if command == "infer" else
            [model, "train", "--data", tiny["data"], "--workdir", work])
    rc, err, _ = run(argv, capsys)
    assert rc == 2 and err == (f"jaxgest: {work}: written by a newer jaxgest (workdir format 2, this version "
                               "reads up to 1); upgrade jaxgest, or retrain into a new --workdir"), err
    assert snapshot(work) == before


def test_checkpoint_from_a_newer_version(tiny, capsys, tmp_path):
    work = copy(tiny, "zeggs", tmp_path)
    _edit_meta(work, "zeggs", lambda d: d.update(format_version=FORMAT_VERSION + 1))
    rc, err, _ = run(infer(tiny, "zeggs", work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and "checkpoint written by a newer jaxgest (format version 2; this one reads up to 1)" in err


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_unknown_model_kind(tiny, capsys, tmp_path, model):
    work = copy(tiny, model, tmp_path)
    _edit_config(work, lambda d: d.update(model="gesturenet"))
    rc, err, _ = run(infer(tiny, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and err == (f"jaxgest: {work}: config.json names 'gesturenet' (this jaxgest knows tgst, zeggs): "
                               "an older layout or not a jaxgest workdir; retrain into a new --workdir"), err


@pytest.mark.parametrize("model,field", [("tgst", "edge_frames")])
def test_older_layout_without_a_current_field(tiny, capsys, tmp_path, model, field):
    """A workdir written before ``field`` (of the model config) existed (absent from config.json and from the
    checkpoints)."""
    work = copy(tiny, model, tmp_path)
    _edit_config(work, lambda d: (d["config"]["model"] if model == "tgst" else d["config"]).pop(field))
    for stage in (("autoencoder", "transformer") if model == "tgst" else ("zeggs",)):
        _edit_meta(work, stage, lambda d: d["config"].pop(field, None))
    rc, err, _ = run(infer(tiny, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and "checkpoint from an older version of jaxgest (config without" in err and field in err, err
    assert err.endswith("retrain into a new --workdir with this version (checkpoints are not converted)"), err


def test_older_zeggs_layout_without_a_current_field_still_generates(tiny, capsys, tmp_path):
    """ZeroEGGS reads its checkpoint against config.json as stored: a workdir written before a (training-only)
    field existed still generates, with no output on stderr (fields that change inference have legacy values in
    jaxgest.zeggs.config.LEGACY_DEFAULTS, tested in test_zeggs_model/test_zeggs_api)."""
    work = copy(tiny, "zeggs", tmp_path)
    _edit_config(work, lambda d: d["config"]["train"].pop("style_window_max"))
    _edit_meta(work, "zeggs", lambda d: d["config"].pop("style_window_max", None))
    rc, err, _ = run(infer(tiny, "zeggs", work, tmp_path / "o.bvh"), capsys)
    assert rc == 0 and err == "", err
    assert (tmp_path / "o.bvh").is_file()


def test_config_with_an_unknown_field(tiny, capsys, tmp_path):
    work = copy(tiny, "zeggs", tmp_path)
    _edit_config(work, lambda d: d["config"].update(future_knob=3))
    rc, err, _ = run(infer(tiny, "zeggs", work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and err.startswith(f"jaxgest: {work}/config.json: config from another version of jaxgest"), err
    assert "future_knob" in err and err.endswith("retrain into a new --workdir")


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_truncated_config_json(tiny, capsys, tmp_path, model):
    work = copy(tiny, model, tmp_path)
    text = (work / "config.json").read_text()
    (work / "config.json").write_text(text[: len(text) // 2])
    rc, err, _ = run(infer(tiny, model, work, tmp_path / "o.bvh"), capsys)
    assert rc == 2 and err == (f"jaxgest: {work}/config.json: unreadable (not valid JSON: truncated or "
                               "corrupted?); restore it from a backup or retrain into a new --workdir"), err
    # training rewrites config.json (the checkpoints carry their own config): nothing to train, file repaired
    steps = ["--ae-steps", 4, "--transformer-steps", 4] if model == "tgst" else ["--steps", 4]
    rc, err, out = run([model, "train", "--data", tiny["data"], "--workdir", work, *steps], capsys)
    assert rc == 0 and err == "" and "nothing to do" in out, (err, out)
    assert json.loads((work / "config.json").read_text())["format_version"] == FORMAT_VERSION

"""Bad input through the command line: exit status 2, ONE line on stderr naming the file and the problem.

Every case runs ``jaxgest.cli.main([...])`` in-process on the session's tiny trained models (conftest:
TGST 4+4 steps, ZeroEGGS 4 steps on the synthetic data; a case that changes a workdir copies it) and
checks: status 2; stderr is exactly one line (the CLI drops progress bars when stderr is not a terminal)
starting with ``jaxgest: ``, naming the file (or the argument) and the problem, with no traceback; and the
output folder holds no new file (no partial or temporary output).

Documented behaviours checked here as successes: silent speech generates (finite features, SPEC §4), audio
at any sample rate or channel count is resampled, and audio/motion lengths of a training clip may differ by
up to ``jaxgest.zeggs.data.LENGTH_TOLERANCE_S`` (1 s; both are cut to the shorter), more is an error.
"""

from __future__ import annotations

import json
import pathlib
import re
import shutil

import numpy as np
import pytest
import soundfile as sf

from jaxgest import cli
from jaxgest.motion import bvh


@pytest.fixture(scope="module")
def ctx(tiny, zeggs_pca_workdir, tmp_path_factory):
    """The session's synthetic data and tiny TGST/ZeroEGGS workdirs (one with a PCA), and a folder of bad
    files."""
    root = tmp_path_factory.mktemp("bad_input")
    data, tw, zw, zp = tiny["data"], tiny["tw"], tiny["zw"], zeggs_pca_workdir

    bad = root / "bad"
    bad.mkdir()
    good = data / "greeting_neutral_0.bvh"
    text = good.read_text()
    lines = text.splitlines(keepends=True)
    motion_at = next(i for i, x in enumerate(lines) if x.startswith("MOTION"))
    first = motion_at + 3  # first frame line
    files = {
        "empty.bvh": "",
        "truncated.bvh": "".join(lines[:first + 20]),  # says 180 frames, has 20
        "letters.bvh": "".join(lines[:first + 2] + [re.sub(r"^(\S+ \S+) \S+", r"\1 abc", lines[first + 2])]
                               + lines[first + 3:]),
        "unbalanced.bvh": "".join(x for i, x in enumerate(lines) if not (i < motion_at and x.strip() == "}"
                                                                         and i == motion_at - 1)),
        "short_line.bvh": "".join(lines[:first + 1] + [" ".join(lines[first + 1].split()[:-1]) + "\n"]
                                  + lines[first + 2:]),
        "nan.bvh": "".join(lines[:first + 5] + [re.sub(r"^(\S+) (\S+)", r"\1 nan", lines[first + 5])]
                           + lines[first + 6:]),
        "short.bvh": "".join(lines[:motion_at + 1] + ["Frames: 5\n", lines[motion_at + 2]]
                             + lines[first:first + 5]),
        "unmapped.bvh": (
            "HIERARCHY\nROOT Base\n{\n\tOFFSET 0 0 0\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation "
            "Xrotation Yrotation\n\tJOINT Arm\n\t{\n\t\tOFFSET 0 10 0\n\t\tCHANNELS 3 Zrotation Xrotation "
            "Yrotation\n\t\tEnd Site\n\t\t{\n\t\t\tOFFSET 0 5 0\n\t\t}\n\t}\n}\nMOTION\nFrames: 120\n"
            "Frame Time: 0.0166667\n" + "0 0 0 0 0 0 0 0 0\n" * 120),
    }
    for name, content in files.items():
        (bad / name).write_text(content)
    (bad / "binary.bvh").write_bytes(b"HIERARCHY\x00\x01\x02" * 10)

    y, sr = sf.read(data / "greeting_neutral_0.wav", dtype="float32")
    sf.write(bad / "silent.wav", np.zeros(2 * sr, np.float32), sr)
    nan = y.copy()
    nan[100:200] = np.nan
    sf.write(bad / "nan.wav", nan, sr, subtype="FLOAT")
    sf.write(bad / "empty.wav", np.zeros(0, np.float32), sr)
    (bad / "text.wav").write_text("this is not audio\n")
    import librosa

    sf.write(bad / "rate44k.wav", librosa.resample(y, orig_sr=sr, target_sr=44100), 44100)
    sf.write(bad / "stereo8k.wav", np.stack([librosa.resample(y, orig_sr=sr, target_sr=8000)] * 2, 1), 8000)
    return {"data": data, "tw": tw, "zw": zw, "zp": zp, "bad": bad, "good": good, "root": root,
            "wav": data / "greeting_neutral_0.wav", "style2": data / "greeting_sad_0.bvh"}


def _snapshot(folder: pathlib.Path) -> set:
    return {p.name for p in folder.iterdir()} if folder.is_dir() else set()


def run_cli(argv, capsys, out=None):
    """``(status, stderr message line)``; checks there is one line and that ``out``'s folder is unchanged."""
    folder = pathlib.Path(out).parent if out else None
    before = _snapshot(folder) if folder else None
    capsys.readouterr()
    rc = cli.main([str(a) for a in argv])
    captured = capsys.readouterr()
    err = captured.err
    if folder and rc != 0:
        assert _snapshot(folder) == before, "the failed command left files behind"
    assert "Traceback" not in err
    if rc != 0:
        assert err.count("\n") == 1 and err.endswith("\n") and "\r" not in err, repr(err)
        assert err.startswith("jaxgest: "), repr(err)
        return rc, err.rstrip("\n")
    return rc, captured.out


def _out(ctx, name="out.bvh"):
    folder = ctx["root"] / "out"
    folder.mkdir(exist_ok=True)
    return folder / name


def _transfer(ctx, content, style=None, out=None, workdir=None):
    return ["tgst", "transfer", "--workdir", workdir or ctx["tw"], "--content", content,
            "--style", style or ctx["good"], "--out", out]


def _generate(ctx, *, audio=None, styles=None, out=None, workdir=None, extra=()):
    argv = ["zeggs", "generate", "--workdir", workdir or ctx["zw"], "--audio", audio or ctx["wav"]]
    for s in styles or [ctx["good"]]:
        argv += ["--style", s]
    return argv + ["--out", out] + list(extra)


# (case id, bad file name, expected pieces of the message)
BVH_CASES = [
    ("empty", "empty.bvh", ["empty.bvh"]),
    ("truncated", "truncated.bvh", ["truncated.bvh", "180"]),
    ("letters", "letters.bvh", ["letters.bvh:", "'abc'"]),
    ("unbalanced", "unbalanced.bvh", ["unbalanced.bvh"]),
    ("short_line", "short_line.bvh", ["short_line.bvh:"]),
    ("binary", "binary.bvh", ["binary.bvh: binary data, not a BVH text file"]),
    ("nan", "nan.bvh", ["nan.bvh:", "motion row contains NaN or inf"]),
    ("missing", "does_not_exist.bvh", ["does_not_exist.bvh: no such file"]),
    ("unmapped", "unmapped.bvh", ["unmapped.bvh: content skeleton does not fit any joint map",
                                  "matches no joint map"]),
    ("too_short", "short.bvh", ["short.bvh: content clip too short: 5 frames"]),
]


@pytest.mark.parametrize("case,name,expected", BVH_CASES, ids=[c[0] for c in BVH_CASES])
def test_bad_bvh_as_tgst_content(ctx, capsys, case, name, expected):
    out = _out(ctx)
    rc, msg = run_cli(_transfer(ctx, ctx["bad"] / name, out=out), capsys, out)
    assert rc == 2 and all(e in msg for e in expected), msg
    assert not out.exists()


@pytest.mark.parametrize("case,name,expected", [
    ("truncated", "truncated.bvh", ["truncated.bvh", "180"]),
    ("nan", "nan.bvh", ["nan.bvh:", "motion row contains NaN or inf"]),
    ("too_short", "short.bvh", ["short", "is too short for a style example"]),
    ("unmapped", "unmapped.bvh", ["unmapped", "matches no joint map"]),
])
def test_bad_bvh_as_zeggs_style(ctx, capsys, case, name, expected):
    out = _out(ctx)
    rc, msg = run_cli(_generate(ctx, styles=[ctx["bad"] / name], out=out), capsys, out)
    assert rc == 2 and all(e in msg for e in expected), msg
    assert not out.exists()


def test_bad_bvh_as_tgst_style(ctx, capsys):
    out = _out(ctx)
    rc, msg = run_cli(_transfer(ctx, ctx["good"], style=ctx["bad"] / "short.bvh", out=out), capsys, out)
    assert rc == 2 and "short.bvh: style clip too short" in msg, msg


# ----- audio ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name,expected", [
    ("nan.wav", "nan.wav: audio contains NaN or inf samples"),
    ("empty.wav", "empty.wav: empty audio (no samples)"),
    ("text.wav", "text.wav: unreadable audio"),
    ("missing.wav", "missing.wav: no such audio file"),
])
def test_bad_audio(ctx, capsys, name, expected):
    out = _out(ctx)
    rc, msg = run_cli(_generate(ctx, audio=ctx["bad"] / name, out=out), capsys, out)
    assert rc == 2 and expected in msg, msg
    assert not out.exists()


@pytest.mark.parametrize("name", ["silent.wav", "rate44k.wav", "stereo8k.wav"])
def test_silent_or_resampled_audio_generates(ctx, capsys, name):
    """Silent speech has finite features (SPEC §4) and generates; other rates / stereo are resampled."""
    out = _out(ctx, f"gen_{name}.bvh")
    rc, stdout = run_cli(_generate(ctx, audio=ctx["bad"] / name, out=out), capsys)
    assert rc == 0, stdout
    m = bvh.load(out)
    info = sf.info(ctx["bad"] / name)
    assert abs(m.num_frames - info.duration * m.fps) <= 1  # the length of the speech, at the style's rate
    assert np.all(np.isfinite(m.rotations)) and np.all(np.isfinite(m.translations))


# ----- training folders -------------------------------------------------------------------------------------

def _folder_with_short_audio(ctx, tmp_path, cut_s):
    folder = tmp_path / "data"
    shutil.copytree(ctx["data"], folder)
    wav = folder / "greeting_sad_0.wav"
    y, sr = sf.read(wav, dtype="float32")
    sf.write(wav, y[: len(y) - int(cut_s * sr)], sr)
    return folder


def test_training_audio_within_the_length_tolerance_trains(ctx, capsys, tmp_path):
    folder = _folder_with_short_audio(ctx, tmp_path, 0.5)
    rc, stdout = run_cli(["zeggs", "train", "--data", folder, "--workdir", tmp_path / "w", "--steps", "0"],
                         capsys)
    assert rc == 0 and "data checked" in stdout and "no steps requested" in stdout


def test_tgst_training_without_data_writes_the_builtin_synthetic_data_once(capsys, tmp_path):
    """Without --data, training writes the built-in synthetic set (all 42 clips) into the workdir, through a
    temporary folder renamed when complete, and a second run reuses it (the shared
    ``synthetic.training_folder``; TGST reads the set faster than ZeroEGGS, whose wiring is checked below)."""
    work = tmp_path / "w"
    rc, stdout = run_cli(["tgst", "train", "--workdir", work, "--steps", "0"], capsys)
    assert rc == 0 and f"built-in synthetic data in {work / 'synthetic-data'}" in stdout, stdout
    assert "autoencoder no steps requested" in stdout
    assert json.loads((work / "config.json").read_text())["data"] == str(work / "synthetic-data")
    assert len(list((work / "synthetic-data").glob("*.bvh"))) == 42 and (work / "synthetic-data/manifest.csv").is_file()
    assert not list(work.glob(".synthetic-data.tmp-*"))  # written to a temporary folder, then renamed
    marker = work / "synthetic-data" / "manifest.csv"
    stamp = marker.stat().st_mtime_ns
    rc, stdout = run_cli(["tgst", "train", "--workdir", work, "--steps", "0"], capsys)  # reused, not rewritten
    assert rc == 0 and "autoencoder no steps requested" in stdout
    assert marker.stat().st_mtime_ns == stamp


def test_zeggs_training_without_data_uses_the_builtin_synthetic_data(ctx, capsys, tmp_path):
    """ZeroEGGS without --data trains on ``<workdir>/synthetic-data`` (here already present -- a small copy, so
    the check does not build features for all 42 clips; writing it is checked with TGST above)."""
    work = tmp_path / "w"
    work.mkdir()
    shutil.copytree(ctx["data"], work / "synthetic-data")
    rc, stdout = run_cli(["zeggs", "train", "--workdir", work, "--steps", "0"], capsys)
    assert rc == 0 and f"built-in synthetic data in {work / 'synthetic-data'}" in stdout, stdout
    assert "no steps requested" in stdout
    assert json.loads((work / "config.json").read_text())["data"] == str(work / "synthetic-data")


@pytest.mark.parametrize("model", ["zeggs", "tgst"])
def test_training_without_data_checks_arguments_first_and_keeps_the_recorded_data(ctx, capsys, tmp_path, model):
    work = tmp_path / "w"
    rc, msg = run_cli([model, "train", "--workdir", work, "--steps", "-3"], capsys)
    assert rc == 2 and "must be >= 0, got -3" in msg and not (work / "synthetic-data").exists(), msg
    work.mkdir()
    (work / "config.json").write_text(json.dumps({"data": str(ctx["data"])}))
    rc, msg = run_cli([model, "train", "--workdir", work, "--steps", "0"], capsys)
    assert rc == 2 and f"was trained on {ctx['data']}; pass --data {ctx['data']} to resume" in msg, msg
    assert not (work / "synthetic-data").exists()


@pytest.mark.parametrize("model", ["zeggs", "tgst"])
@pytest.mark.parametrize("flag", ["--ckpt-every", "--log-every"])
def test_training_with_a_non_positive_interval(ctx, capsys, tmp_path, flag, model):
    work = tmp_path / "w"
    rc, msg = run_cli([model, "train", "--data", ctx["data"], "--workdir", work, "--steps", "1", flag, "0"],
                      capsys)
    assert rc == 2 and f"{flag[2:].replace('-', '_')} must be a positive number of steps, got 0" in msg, msg
    assert not (work / "checkpoints").exists()


def test_training_with_negative_steps(ctx, capsys, tmp_path):
    rc, msg = run_cli(["zeggs", "train", "--data", ctx["data"], "--workdir", tmp_path / "w", "--steps", "-3"], capsys)
    assert rc == 2 and "steps must be >= 0, got -3" in msg, msg


def test_training_audio_beyond_the_length_tolerance(ctx, capsys, tmp_path):
    folder = _folder_with_short_audio(ctx, tmp_path, 1.5)
    work = tmp_path / "w"
    rc, msg = run_cli(["zeggs", "train", "--data", folder, "--workdir", work, "--steps", "0"], capsys)
    assert rc == 2 and "greeting_sad_0.bvh: audio (1.50 s) and motion (3.00 s) lengths differ by more than " \
                       "1.0 s" in msg, msg
    assert not (work / "checkpoints").exists()


def test_training_folder_with_a_malformed_bvh(ctx, capsys, tmp_path):
    folder = tmp_path / "data"
    shutil.copytree(ctx["data"], folder)
    (folder / "greeting_sad_0.bvh").write_text((ctx["bad"] / "truncated.bvh").read_text())
    for model in ("tgst", "zeggs"):
        argv = [model, "train", "--data", folder, "--workdir", tmp_path / model, "--steps", "0"]
        rc, msg = run_cli(argv, capsys)
        assert rc == 2 and "greeting_sad_0.bvh" in msg, msg


# ----- blend weights, PCA -----------------------------------------------------------------------------------

@pytest.mark.parametrize("weights,expected", [
    ("0.5", "blend weights: got 1 weight(s) for 2 style clip(s)"),
    ("0.2,0.3,0.5", "blend weights: got 3 weight(s) for 2 style clip(s)"),
    ("0,0 --normalize-weights", "normalised blend weights must have a positive sum"),  # raw 0,0 is e = 0
    ("nan,1", "blend weights must be finite"),
    ("a,b", "--weights 'a,b': expected comma-separated numbers"),
])
def test_bad_blend_weights(ctx, capsys, weights, expected):
    out = _out(ctx)
    rc, msg = run_cli(_generate(ctx, styles=[ctx["good"], ctx["style2"]], out=out,
                                extra=["--weights", *weights.split()]), capsys, out)
    assert rc == 2 and expected in msg, msg


def test_pca_component_that_does_not_exist(ctx, capsys):
    out = _out(ctx)
    rc, msg = run_cli(_generate(ctx, workdir=ctx["zp"], out=out, extra=["--pca-edit", "99=1.0"]), capsys, out)
    expected = r"PCA component 99 does not exist \(the fitted PCA has components 0\.\.\d+\)"
    assert rc == 2 and re.search(expected, msg), msg
    rc, msg = run_cli(_generate(ctx, workdir=ctx["zp"], out=out, extra=["--pca-edit", "0=1.0"]), capsys, out)
    assert rc == 0 and out.exists()  # an existing component works
    out.unlink()


def test_pca_edit_without_a_fitted_pca(ctx, capsys):
    out = _out(ctx)
    rc, msg = run_cli(_generate(ctx, out=out, extra=["--pca-edit", "0=1.0"]), capsys, out)
    assert rc == 2 and "pca.json: no PCA fitted yet (run `jaxgest zeggs pca" in msg, msg


# ----- workdirs and checkpoints -----------------------------------------------------------------------------

def test_workdir_without_anything(ctx, capsys, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    out = _out(ctx)
    rc, msg = run_cli(_transfer(ctx, ctx["good"], out=out, workdir=empty), capsys, out)
    assert rc == 2 and f"{empty}: not a TGST workdir" in msg, msg
    rc, msg = run_cli(_generate(ctx, out=out, workdir=empty), capsys, out)
    assert rc == 2 and f"{empty}: no ZeroEGGS model here" in msg, msg


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_workdir_whose_checkpoints_are_gone(ctx, capsys, tmp_path, model):
    work = tmp_path / "w"
    shutil.copytree(ctx["tw" if model == "tgst" else "zw"], work)
    shutil.rmtree(work / "checkpoints")
    out = _out(ctx)
    argv = _transfer(ctx, ctx["good"], out=out, workdir=work) if model == "tgst" else _generate(
        ctx, out=out, workdir=work)
    rc, msg = run_cli(argv, capsys, out)
    assert rc == 2 and str(work) in msg and "no checkpoint" in msg, msg


def test_workdir_of_the_other_model(ctx, capsys):
    out = _out(ctx)
    rc, msg = run_cli(_transfer(ctx, ctx["good"], out=out, workdir=ctx["zw"]), capsys, out)
    assert rc == 2 and f"{ctx['zw']}: a zeggs workdir, not a TGST one" in msg, msg
    rc, msg = run_cli(_generate(ctx, out=out, workdir=ctx["tw"]), capsys, out)
    assert rc == 2 and str(ctx["tw"]) in msg and "not a ZeroEGGS model" in msg, msg


@pytest.mark.parametrize("model", ["tgst", "zeggs"])
def test_checkpoint_of_another_preset(ctx, capsys, tmp_path, model):
    work = tmp_path / "w"
    shutil.copytree(ctx["tw" if model == "tgst" else "zw"], work)
    before = {p: p.read_bytes() for p in work.rglob("*") if p.is_file()}
    other = "fit-motion" if model == "tgst" else "paper"  # TGST's paper preset has the tiny one's networks
    rc, msg = run_cli([model, "train", "--data", ctx["data"], "--workdir", work, "--preset", other,
                       "--steps", "0"], capsys)
    assert rc == 2 and "checkpoint does not match the requested model" in msg
    assert "use another --workdir" in msg
    assert str(work) in msg
    assert {p: p.read_bytes() for p in work.rglob("*") if p.is_file()} == before  # nothing was touched


# ----- output paths -----------------------------------------------------------------------------------------

def test_output_in_a_missing_directory(ctx, capsys):
    missing = ctx["root"] / "no_such_dir"
    cases = [
        (_transfer(ctx, ctx["good"], out=missing / "o.bvh"), missing / "o.bvh"),
        (_generate(ctx, out=missing / "o.bvh"), missing / "o.bvh"),
        (["render", ctx["good"], "--out", missing / "o.gif"], missing / "o.gif"),
        (["zeggs", "evaluate", "--workdir", ctx["zw"], "--data", ctx["data"], "--json", missing / "o.json"],
         missing / "o.json"),
        (["tgst", "evaluate", "--workdir", ctx["tw"], "--data", ctx["data"], "--json", missing / "o.json"],
         missing / "o.json"),
    ]
    for argv, out in cases:
        rc, msg = run_cli(argv, capsys)
        assert rc == 2 and f"{out}: output directory {missing} does not exist" in msg, (argv[:2], msg)
    assert not missing.exists()


def test_good_transfer_still_works(ctx, capsys):
    """The sweep above is not failing for an unrelated reason: the same commands succeed on good input."""
    out = _out(ctx, "ok.bvh")
    rc, stdout = run_cli(_transfer(ctx, ctx["good"], style=ctx["style2"], out=out), capsys)
    assert rc == 0 and out.exists() and bvh.load(out).num_frames == bvh.load(ctx["good"]).num_frames
    out2 = _out(ctx, "ok_gen.bvh")
    rc, stdout = run_cli(_generate(ctx, styles=[ctx["good"], ctx["style2"]], out=out2,
                                   extra=["--weights", "0.3,0.7"]), capsys)
    assert rc == 0 and out2.exists()

"""ZeroEGGS end to end on tiny synthetic data: train, resume, generate (API + CLI), blends, seeds, PCA, errors.

The tests use the session's tiny model (tests/conftest.py: 4 steps, checkpoints 2 and 4, metrics every step)
and its compilations; a test that trains further or writes into the workdir works on a copy.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import soundfile as sf

from jaxgest.runtime import provenance
from jaxgest.runtime.errors import CheckpointError, JaxgestError
from jaxgest.motion import bvh
from tiny_models import train_zeggs

@pytest.fixture(scope="module")
def trained(tiny_data, zeggs_trained):
    """``(data, workdir, summary)`` of the session's tiny ZeroEGGS; read-only."""
    return (tiny_data, *zeggs_trained)


@pytest.fixture(scope="module")
def clips(trained):
    data, _, _ = trained
    styles = [bvh.load(p) for p in sorted(data.glob("*.bvh"))[:2]]
    audio = sorted(data.glob("*.wav"))[0]
    return styles, audio


@pytest.fixture(scope="module")
def with_pca(zeggs_pca_workdir):
    """The trained workdir with a PCA of its style embeddings (``jaxgest zeggs pca``); read-only."""
    return zeggs_pca_workdir


def test_api_matches_spec():
    from jaxgest.zeggs import api, inference

    assert api.load_model is inference.load_model
    assert set(api.count_params("tiny")) == {"speech_encoder", "style_encoder", "generator"}
    import inspect

    sig = inspect.signature(api.generate)
    assert list(sig.parameters)[:2] == ["audio", "styles"]
    for name, default in (("weights", None), ("seed", 0), ("temperature", 1.0)):
        assert sig.parameters[name].kind is inspect.Parameter.KEYWORD_ONLY and sig.parameters[name].default == default
    assert sig.parameters["workdir"].default is inspect.Parameter.empty


def test_training_writes_everything_and_resumes(trained, copy_workdir):
    from jaxgest.zeggs.trainer import train

    data, work, summary = trained
    for name in ("config.json", "metrics.jsonl", "pose_stats.json", "speech_stats.json", "reference.bvh"):
        assert (work / name).is_file(), name
    code = json.loads((work / "config.json").read_text())["code"]  # the code that trained it (issue 59)
    assert code["commit"] == provenance.commit_of()[0] and {"version", "cpu", "threads", "command"} <= set(code)
    lines = [json.loads(x) for x in (work / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in lines] == [1, 2, 3, 4] and all(np.isfinite(r["loss"]) for r in lines)
    assert lines[0]["devices"] == 1 and summary["start_step"] == 0 and summary["steps"] == 4
    # training and inference settings may change on resume (the checkpoint carries the model config only)
    work = copy_workdir(work)
    again = train(data, work, preset="tiny", steps=8, progress=False, log_every=2, ckpt_every=2,
                  overrides={"train.learning_rate": 2e-3, "train.style_sampling": "overlap",
                             "inference.temperature": 0.5})
    assert again["start_step"] == 4 and np.isfinite(again["final"]["loss"])
    stored = json.loads((work / "config.json").read_text())["config"]
    assert stored["train"]["learning_rate"] == 2e-3 and stored["inference"]["temperature"] == 0.5
    lines = [json.loads(x) for x in (work / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in lines][-1] == 8
    with pytest.raises(CheckpointError, match="does not match"):
        train(data, work, preset="tiny", steps=8, progress=False, overrides={"model.gru_hidden": 16})


def test_training_again_in_one_process_reuses_the_compiled_step(trained, tmp_path, monkeypatch):
    """jit's own cache serves every training of one config in a process (zeggs/train.py builds its step at
    module level, the config static, the state without optimiser object): over two trainings into fresh
    workdirs the step is traced at most once (none when the session's training already traced it), i.e. the
    second training traces nothing."""
    from jaxgest.zeggs import trainer as ztrain

    traces = []
    real = ztrain.make_train_step  # called only while jit traces the step
    monkeypatch.setattr(ztrain, "make_train_step", lambda cfg: traces.append(cfg) or real(cfg))
    runs = [train_zeggs(trained[0], tmp_path / "a", steps=1)]
    first = len(traces)
    runs.append(train_zeggs(trained[0], tmp_path / "b", steps=1))
    assert all(r["steps"] == 1 and np.isfinite(r["final"]["loss"]) for r in runs)
    assert first <= 1 and len(traces) == first, (first, len(traces))


def test_generate_length_rig_and_seeds(trained, clips):
    from jaxgest.zeggs.api import generate

    _, work, _ = trained
    styles, audio = clips
    m = generate(audio, styles[0], workdir=work, seed=0)
    info = sf.info(str(audio))
    assert m.num_frames == round(info.frames / info.samplerate * styles[0].fps)
    assert m.fps == styles[0].fps
    assert m.skeleton.names == styles[0].skeleton.names and np.all(np.isfinite(m.rotations))
    same = generate(audio, [styles[0]], workdir=work, seed=0)
    other = generate(audio, [styles[0]], workdir=work, seed=1)
    np.testing.assert_array_equal(m.rotations, same.rotations)
    np.testing.assert_array_equal(m.translations, same.translations)
    assert np.abs(m.rotations - other.rotations).max() > 1e-4
    cold = generate(audio, [styles[0]], workdir=work, seed=1, temperature=0.0)  # the posterior mean
    np.testing.assert_array_equal(cold.rotations, generate(audio, [styles[0]], workdir=work, seed=2,
                                                           temperature=0.0).rotations)


def test_padded_lengths_are_exact(trained, clips):
    """Sequences padded to shared bucket lengths give the same result as the exact length."""
    import jax.numpy as jnp

    from jaxgest.zeggs.inference import bucket_length, load_model

    _, work, _ = trained
    styles, audio = clips
    assert [bucket_length(n) for n in (1, 64, 65, 97, 600)] == [64, 64, 96, 128, 768]
    model = load_model(work)
    x = jnp.asarray(model.style_features(styles[0]))[None, :70]
    mu, logvar = model.encode_style(model.params, x, jnp.ones((1, 70), bool))  # padded to 96
    mu0, logvar0 = model.fns["encode_style"](model.params, x, jnp.ones((1, 70), bool))
    np.testing.assert_allclose(mu, mu0, atol=1e-5)
    np.testing.assert_allclose(logvar, logvar0, atol=1e-5)
    speech, _ = model.speech(audio)
    s = model.encode_speech(model.params, jnp.asarray(speech)[None, :70])
    args = (mu, x[:, 0], jnp.zeros((1, 3)), jnp.asarray([[1.0, 0, 0, 0]]), jnp.asarray([[0.0, 0, 1]]),
            model.pose_mean, model.pose_std)
    padded = model.run_generator(model.params, s, *args)
    exact = model.fns["generate"](model.params, s, *args)
    for k in exact:
        assert padded[k].shape == exact[k].shape
        np.testing.assert_allclose(padded[k], exact[k], atol=1e-5)


def test_generate_from_bvh_paths_and_audio_arrays(trained, clips):
    from jaxgest.zeggs.api import generate

    data, work, _ = trained
    styles, audio = clips
    path = sorted(data.glob("*.bvh"))[0]
    y, sr = sf.read(str(audio), dtype="float32")
    a = generate(audio, str(path), workdir=work, seed=3)
    b = generate((y, sr), [path], workdir=work, seed=3)
    np.testing.assert_allclose(a.rotations, b.rotations, atol=1e-5)
    with pytest.raises(JaxgestError, match="no such audio file"):
        generate(data / "missing.wav", styles[0], workdir=work)
    with pytest.raises(JaxgestError, match="Motion or a BVH path"):
        generate(audio, [42], workdir=work)


def test_blend_weights(trained, clips):
    from jaxgest.zeggs.api import generate
    from jaxgest.zeggs.inference import load_model

    _, work, _ = trained
    styles, audio = clips
    model = load_model(work)
    e1, e2 = (model.style_embedding([s], seed=5) for s in styles)
    assert np.abs(e1 - e2).max() > 1e-4  # two different clips, two different embeddings
    np.testing.assert_array_equal(model.style_embedding(styles, weights=[1, 0], seed=5), e1)
    # Weights are used as given: (2, 0) scales the first embedding (paper §5.2.1), (0, 0) is e = 0;
    # normalize_weights=True divides by their sum (the old behaviour).
    np.testing.assert_array_equal(model.style_embedding(styles, weights=[2, 0], seed=5), 2 * e1)
    np.testing.assert_array_equal(model.style_embedding(styles, weights=[0, 0], seed=5), 0 * e1)
    np.testing.assert_array_equal(model.style_embedding(styles, weights=[2, 0], seed=5, normalize_weights=True), e1)
    half = model.style_embedding(styles, weights=[0.5, 0.5], seed=5, temperature=0.0)
    mu1, mu2 = (model.style_embedding([s], temperature=0.0) for s in styles)
    np.testing.assert_allclose(half, 0.5 * (mu1 + mu2), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(model.style_embedding(styles, weights=[1, 3], temperature=0.0, normalize_weights=True),
                               0.25 * mu1 + 0.75 * mu2, rtol=1e-5, atol=1e-6)
    first = generate(audio, styles, workdir=work, weights=[1, 0], seed=5)
    alone = generate(audio, styles[:1], workdir=work, seed=5)
    np.testing.assert_array_equal(first.rotations, alone.rotations)
    with pytest.raises(JaxgestError, match="2 weight"):
        generate(audio, styles[:1], workdir=work, weights=[0.5, 0.5])
    with pytest.raises(JaxgestError, match="positive sum"):
        generate(audio, styles, workdir=work, weights=[0, 0], normalize_weights=True)
    with pytest.raises(JaxgestError, match="finite"):
        generate(audio, styles, workdir=work, weights=[np.nan, 1])


def test_pca_zero_edit_is_identity_and_bad_component_is_clear(with_pca, clips):
    """(The direction of an edit is tested on a trained model in test_zeggs_style_control.py.)"""
    from jaxgest.zeggs.api import generate

    work = with_pca
    styles, audio = clips
    base = generate(audio, styles[0], workdir=work, seed=0)
    zero = generate(audio, styles[0], workdir=work, seed=0, pca_edits={0: 0.0})
    np.testing.assert_allclose(zero.rotations, base.rotations, atol=1e-4)
    with pytest.raises(JaxgestError, match="component 42 does not exist"):
        generate(audio, styles[0], workdir=work, pca_edits={42: 1.0})


def test_unmapped_style_rig_error_names_the_clip(trained, clips, tmp_path):
    from jaxgest.zeggs.api import generate

    _, work, _ = trained
    _, audio = clips
    path = tmp_path / "odd_rig.bvh"
    path.write_text(
        "HIERARCHY\nROOT Base\n{\n\tOFFSET 0 0 0\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation "
        "Xrotation Yrotation\n\tJOINT Arm\n\t{\n\t\tOFFSET 0 10 0\n\t\tCHANNELS 3 Zrotation Xrotation "
        "Yrotation\n\t\tEnd Site\n\t\t{\n\t\t\tOFFSET 0 5 0\n\t\t}\n\t}\n}\nMOTION\nFrames: 60\n"
        "Frame Time: 0.0166667\n" + "0 0 0 0 0 0 0 0 0\n" * 60)
    with pytest.raises(JaxgestError, match=r"^odd_rig: .*no joint map"):
        generate(audio, path, workdir=work)


def test_missing_workdir_is_clear(tmp_path, clips):
    from jaxgest.zeggs.api import generate

    styles, audio = clips
    with pytest.raises(CheckpointError, match="no ZeroEGGS model"):
        generate(audio, styles[0], workdir=tmp_path / "none")


def test_evaluate_reports_the_three_figures(trained, tmp_path):
    from jaxgest.zeggs.evaluate import evaluate, markdown

    data, work, _ = trained
    rows = ["path,content,style,audio"]
    for i, p in enumerate(sorted(data.glob("*.bvh"))):  # two labelled styles of two clips each
        rows.append(f"{p.resolve()},c{i},{'ab'[i % 2]},{p.with_suffix('.wav').resolve()}")
    (tmp_path / "manifest.csv").write_text("\n".join(rows) + "\n")
    r = evaluate(work, tmp_path, max_clips=1, progress=False)
    assert r["probe"]["chance"] == 0.5 and r["probe"]["styles"] == ["a", "b"] and 0 <= r["probe"]["accuracy"] <= 1
    b = r["beat_alignment"]
    assert b["clips"] == 1 and all(0 <= b[k] <= 1 for k in ("generated", "generated_shuffled", "real"))
    d = b["generated_vs_control"]
    assert d["clips"] == 1 and d["standard_error"] == 0.0 and d["clips_above"] == int(d["mean"] > 0)
    assert d["mean"] == pytest.approx(b["generated"] - b["generated_shuffled"], abs=1e-12)
    assert "clips above)" in markdown(r)
    f = r["frechet_distance"]
    assert f["generated_vs_real"] > 0 and f["real_train_vs_real_test"] >= 0
    assert "style probe accuracy (chance 0.500)" in markdown(r)


def test_paired_difference_of_beat_scores():
    from jaxgest.zeggs.evaluate import paired_difference

    scores = [{"aligned": 0.7, "shuffled": 0.5}, {"aligned": 0.6, "shuffled": 0.6}, {"aligned": 0.4, "shuffled": 0.5}]
    d = paired_difference(scores)  # differences 0.2, 0.0, -0.1: mean 1/30, sample std sqrt(0.07/3)
    assert d["clips"] == 3 and d["clips_above"] == 1
    assert d["mean"] == pytest.approx(1 / 30) and d["standard_error"] == pytest.approx(np.sqrt(0.07 / 3) / np.sqrt(3))


@pytest.mark.realdata
def test_generate_on_the_zeggs_rig_from_real_audio(trained, zeggs_dir):
    from jaxgest.zeggs.api import generate

    _, work, _ = trained
    style = bvh.load(zeggs_dir / "067_Speech_2_x_1_0.bvh")
    style = style.replace(rotations=style.rotations[:90], translations=style.translations[:90])
    audio = zeggs_dir / "067_Speech_2_x_1_0.wav"
    info = sf.info(str(audio))
    m = generate(audio, [style], workdir=work)
    assert m.skeleton.names == style.skeleton.names and m.fps == 30.0
    assert m.num_frames == round(info.frames / info.samplerate * 30.0)
    assert np.all(np.isfinite(m.rotations))


class _Run:
    """What a command line run left: exit status, stdout, stderr."""

    def __init__(self, returncode, stdout, stderr):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


@pytest.fixture
def run_cli(capsys):
    """``run_cli(args) -> _Run``: ``jaxgest.cli.main`` in this process (its compilations are reused; the
    console script itself is run by tests/integration/test_cli_data.py and the resume tests)."""
    from jaxgest.cli import main

    def run(args):
        capsys.readouterr()
        try:
            rc = main([str(a) for a in args])
        except SystemExit as e:  # argparse
            rc = e.code
        out, err = capsys.readouterr()
        return _Run(rc, out, err)

    return run


@pytest.mark.realdata
def test_cli_generate_with_real_zeggs_audio(trained, zeggs_dir, tmp_path, run_cli):
    data, work, _ = trained
    style = str(sorted(data.glob("*.bvh"))[0])
    audio = zeggs_dir / "067_Speech_2_x_1_0.wav"
    out = tmp_path / "real.bvh"
    r = run_cli(["zeggs", "generate", "--workdir", str(work), "--audio", str(audio), "--style", style,
                 "--out", str(out)])
    assert r.returncode == 0, r.stderr
    info = sf.info(str(audio))
    m = bvh.load(out)
    assert m.num_frames == round(info.frames / info.samplerate * bvh.load(style).fps)
    assert m.skeleton.names == bvh.load(style).skeleton.names


@pytest.mark.slow
def test_cli_generate_pca_and_errors(trained, tmp_path, copy_workdir, run_cli):
    data, work, _ = trained
    work = copy_workdir(work)
    style = str(sorted(data.glob("*.bvh"))[0])
    audio = str(sorted(data.glob("*.wav"))[0])
    r = run_cli(["zeggs", "pca", "--workdir", str(work), "--data", str(data), "--window", "1"])
    assert r.returncode == 0, r.stderr
    assert "explained variance" in r.stdout and (work / "pca.json").is_file()
    out = tmp_path / "gen.bvh"
    r = run_cli(["zeggs", "generate", "--workdir", str(work), "--audio", audio, "--style", style, "--style", style,
                 "--weights", "0.5,0.5", "--pca-edit", "0=1.5", "--seed", "2", "--out", str(out)])
    assert r.returncode == 0, r.stderr
    assert bvh.load(out).num_frames > 1
    bad = [
        (["--weights", "1,1,1"], "weight"),
        (["--weights", "0,0", "--normalize-weights"], "positive sum"),
        (["--pca-edit", "42=1"], "component 42 does not exist"),
        (["--pca-edit", "zero"], "COMPONENT=DELTA"),
    ]
    for extra, msg in bad:
        out2 = tmp_path / "bad.bvh"
        styles = ["--style", style, "--style", style] if extra[1] == "0,0" else ["--style", style]
        r = run_cli(["zeggs", "generate", "--workdir", str(work), "--audio", audio, *styles,
                     "--out", str(out2)] + extra)
        assert r.returncode == 2 and msg in r.stderr and "Traceback" not in r.stderr, (extra, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1 and not out2.exists()
    r = run_cli(["zeggs", "generate", "--workdir", str(tmp_path / "none"), "--audio", audio, "--style", style,
                 "--out", str(tmp_path / "x.bvh")])
    assert r.returncode == 2 and "no ZeroEGGS model" in r.stderr
    r = run_cli(["zeggs", "train", "--data", str(data), "--workdir", str(tmp_path / "w"),
                 "--override", "gru=3"])
    assert r.returncode == 2 and "unknown ZeroEGGS config field 'gru'" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "w").exists()  # checked before any data is written


def test_train_cli_on_a_finished_workdir_says_nothing_to_do(trained, capsys, copy_workdir):
    from jaxgest.cli import main

    data, work, summary = trained
    work = copy_workdir(work)
    before = (work / "metrics.jsonl").read_text()
    assert main(["zeggs", "train", "--data", str(data), "--workdir", str(work), "--preset", "tiny",
                 "--steps", str(summary["steps"])]) == 0
    out = capsys.readouterr().out
    assert "is already trained to step" in out and "nothing to do" in out and "nan" not in out
    assert (work / "metrics.jsonl").read_text() == before


def test_style_example_prefers_another_content_of_the_same_style():
    from types import SimpleNamespace as C

    from jaxgest.zeggs.evaluate import style_example

    clip = C(style="sad", content="greeting", path="greeting_sad_0.bvh")
    other_content = C(style="sad", content="apology", path="apology_sad_0.bvh")
    same_content = C(style="sad", content="greeting", path="greeting_sad_1.bvh")
    other_style = C(style="proud", content="apology", path="apology_proud_0.bvh")
    assert style_example(clip, [other_style, same_content, other_content]) is other_content
    assert style_example(clip, [other_style, same_content]) is same_content  # another take, same content
    assert style_example(clip, [other_style, clip]) is clip  # nothing else of this style: the clip itself


def _flat_config(cfg) -> dict:
    """The one flat config dict that earlier versions wrote."""
    return {"name": cfg.name, **cfg.model.to_dict(), **{k: v for k, v in cfg.train.to_dict().items() if k != "steps"},
            "temperature": cfg.inference.temperature}


def test_workdir_from_before_a_new_config_field_keeps_its_behaviour(trained, clips, tmp_path):
    """A workdir of an earlier version (one flat config dict in config.json and its checkpoints) loads; a model
    trained before loudness normalisation, group input normalisation and the authors' speech features existed
    generates with unnormalised speech, per-channel inputs and librosa features, as it was trained. So does a
    workdir of the current layout written before ``speech_features`` existed."""
    import shutil

    from jaxgest.zeggs.inference import load_model

    _, work, _ = trained
    new = load_model(work).cfg
    assert new.model.loudness is True and new.model.input_norm == "group" and new.model.fk_parents  # defaults
    assert new.model.speech_features == "authors"
    nested = tmp_path / "nested"  # the current layout, from before speech_features
    shutil.copytree(work, nested)
    meta = json.loads((nested / "config.json").read_text())
    del meta["config"]["model"]["speech_features"]
    (nested / "config.json").write_text(json.dumps(meta))
    for path in nested.glob("checkpoints/zeggs/*/meta/metadata"):
        stored = json.loads(path.read_text())
        del stored["config"]["speech_features"]
        path.write_text(json.dumps(stored))
    model = load_model(nested)
    assert model.cfg.model == new.model.replace(speech_features="librosa")
    styles, audio = clips
    assert np.all(np.isfinite(model.generate(audio, styles[:1]).rotations))
    old = tmp_path / "old"
    shutil.copytree(work, old)
    new_fields = ("loudness", "input_norm", "fk_parents", "fk_offsets", "fk_translated", "w_predicted_position",
                  "speech_features")
    flat = {k: v for k, v in _flat_config(new).items() if k not in new_fields}
    meta = json.loads((old / "config.json").read_text())
    (old / "config.json").write_text(json.dumps({**meta, "config": flat}))
    for path in old.glob("checkpoints/zeggs/*/meta/metadata"):  # as an old run wrote them
        stored = json.loads(path.read_text())
        path.write_text(json.dumps({**stored, "config": {"preset": "tiny", **flat}}))
    model = load_model(old)
    assert model.cfg.model.loudness is False and model.cfg.model.input_norm == "channel"
    assert model.cfg.model.speech_features == "librosa"
    assert model.cfg.model.replace(loudness=True, input_norm="group", fk_parents=new.model.fk_parents,
                                   fk_offsets=new.model.fk_offsets, fk_translated=new.model.fk_translated,
                                   speech_features="authors") == new.model
    assert np.all(np.isfinite(model.generate(audio, styles[:1]).rotations))
    # its checkpoints are compared field by field: resuming with today's defaults names what differs
    from jaxgest.zeggs.trainer import train

    differs = r"does not match the requested model \(.*input_norm: 'channel' -> 'group'"
    with pytest.raises(CheckpointError, match=differs):
        train(trained[0], old, preset="tiny", steps=8, progress=False)


def test_a_loaded_model_owns_its_compiled_functions(trained):
    """load() reads the workdir on every call; each model keeps its own jitted functions (no module-level
    cache); generate takes a path or (samples, rate) for the audio and a path or Motion for the style."""
    from jaxgest.audio import load_audio
    from jaxgest.zeggs.api import load

    data, work, _ = trained
    model, other = load(work), load(work)
    assert model is not other and model.fns is not other.fns
    assert model.fns["generate"] is not other.fns["generate"]
    audio = sorted(data.glob("*.wav"))[0]
    style = sorted(data.glob("*.bvh"))[0]
    a = model.generate(audio, style, seed=1)
    b = model.generate(load_audio(audio), [bvh.load(style)], seed=1)
    np.testing.assert_array_equal(a.rotations, b.rotations)


def test_train_cli_no_loudness_flag_reaches_the_config(monkeypatch):
    from jaxgest.cli import main
    from jaxgest.motion.synthetic import dataset as synthetic_dataset
    from jaxgest.zeggs import trainer as ztrain

    seen = {}

    def fake_train(data, workdir, **kw):
        seen.update(kw)
        return {"final": {}, "start_step": 1, "steps": 1}

    monkeypatch.setattr(ztrain, "train", fake_train)
    monkeypatch.setattr(synthetic_dataset, "training_folder", lambda data, workdir, progress=True: data)
    assert main(["zeggs", "train", "--workdir", "w", "--no-loudness"]) == 0
    assert seen["overrides"] == {"model.loudness": False}
    assert main(["zeggs", "train", "--workdir", "w"]) == 0
    assert seen["overrides"] == {}

"""TGST end to end on tiny synthetic data: train both stages, resume, transfer (API + CLI), evaluate, errors."""

from __future__ import annotations

import dataclasses
import json
import shutil

import jax
import numpy as np
import pytest

from jaxgest import cli
from jaxgest.runtime import provenance
from jaxgest.runtime.errors import CheckpointError, DataError, JaxgestError
from jaxgest.motion import bvh, datasets, kinematics, root_motion
from tiny_models import train_tgst


@pytest.fixture(scope="module")
def trained(tiny_data, tgst_trained):
    """The session's tiny TGST (tests/conftest.py: 4 + 4 steps, checkpoints every 2, metrics every step):
    ``(data, workdir, summary)``; read-only (tests that train further copy the workdir)."""
    return (tiny_data, *tgst_trained)


@pytest.fixture(scope="module")
def model(trained):
    from jaxgest.tgst.api import load_model

    return load_model(trained[1])


def _clips(data):
    return sorted(data.glob("*.bvh"))


def test_train_writes_config_metrics_checkpoints(trained):
    data, work, summary = trained
    cfg = json.loads((work / "config.json").read_text())
    assert cfg["model"] == "tgst" and cfg["preset"] == "tiny" and cfg["devices"] == 1
    assert set(cfg["config"]) == {"name", "model", "train", "inference"}
    # the code that trained it (issue 59): what provenance.code_stamp gives this checkout, and the machine
    assert cfg["code"]["commit"] == provenance.commit_of()[0] and cfg["code"]["version"]
    assert {"cpu", "cores", "threads", "command"} <= set(cfg["code"])
    lines = [json.loads(x) for x in (work / "metrics.jsonl").read_text().splitlines()]
    stages = [(r["stage"], r["step"]) for r in lines]
    assert stages == [("autoencoder", s) for s in (1, 2, 3, 4)] + [("transformer", s) for s in (1, 2, 3, 4)]
    assert all(np.isfinite(r["loss"]) for r in lines)
    assert summary["ae"]["steps"] == 4 and summary["transformer"]["steps"] == 4
    assert (work / "checkpoints/autoencoder").is_dir() and (work / "checkpoints/transformer").is_dir()


def test_resume_continues_from_saved_steps(trained, tmp_path):
    from jaxgest.tgst.trainer import train

    data, work, _ = trained
    copy = tmp_path / "w"
    shutil.copytree(work, copy)
    again = train(data, copy, preset="tiny", ae_steps=4, transformer_steps=6, progress=False, log_every=2,
                  ckpt_every=2)
    assert again["ae"]["start_step"] == 4 and again["ae"]["steps"] == 4  # finished stage 1 not retrained
    assert again["transformer"]["start_step"] == 4 and again["transformer"]["steps"] == 6


def test_training_again_in_one_process_reuses_the_compiled_steps(trained, tmp_path, monkeypatch):
    """jit's own cache serves every training of one config in a process (no memo of jitted steps in
    tgst/train.py): over two trainings into fresh workdirs each stage's step is traced at most once (none when
    the session's training already traced it), i.e. the second training traces nothing."""
    from jaxgest.tgst import trainer as tgst_train

    data = trained[0]
    traces = []
    for name in ("make_ae_train_step", "make_transformer_train_step"):  # called only while jit traces a step
        real = getattr(tgst_train, name)
        monkeypatch.setattr(tgst_train, name,
                            lambda *a, _real=real, _name=name: traces.append(_name) or _real(*a))
    runs = [train_tgst(data, tmp_path / "a", ae_steps=1, transformer_steps=1)]
    first = list(traces)
    runs.append(train_tgst(data, tmp_path / "b", ae_steps=1, transformer_steps=1))
    assert all(r["ae"]["steps"] == 1 and r["transformer"]["steps"] == 1 for r in runs)
    assert len(set(first)) == len(first) and traces == first, traces


def test_another_model_on_same_workdir_is_refused(trained, tmp_path):
    """fit-motion has other networks than tiny (standardised autoencoder, no token positions): refused. paper has the
    same networks and other training settings only, which a workdir may change."""
    from jaxgest.tgst.trainer import train

    data, work, _ = trained
    copy = tmp_path / "w"
    shutil.copytree(work, copy)
    before = (copy / "config.json").read_text()
    with pytest.raises(CheckpointError, match="does not match"):
        train(data, copy, preset="fit-motion", ae_steps=1, transformer_steps=1, progress=False)
    assert (copy / "config.json").read_text() == before  # nothing overwritten


def test_ablation_validated():
    from jaxgest.tgst.config import preset
    from jaxgest.tgst.trainer import apply_ablation

    cfg = apply_ablation(preset("tiny"), ["cyclic", "structure"])
    t = cfg.train.transformer
    assert not t.use_cyclic and not t.use_structure and t.use_identity and t.use_appearance
    assert cfg.model == preset("tiny").model  # an ablation changes the training only
    with pytest.raises(JaxgestError, match="unknown loss term"):
        apply_ablation(preset("tiny"), ["style"])


@pytest.mark.parametrize("method", ["soft", "hard", "adain", "avatarnet"])
def test_transfer_all_methods_keep_content_skeleton_and_length(trained, model, method):
    data, _, _ = trained
    content, style = (bvh.load(p) for p in _clips(data)[:2])
    out = model.transfer(content, style, method=method)
    assert out.skeleton.names == content.skeleton.names and out.num_frames == content.num_frames
    assert out.fps == content.fps and np.all(np.isfinite(out.rotations))
    # floor contact at the content's height (paper §3.1, the default): the lowest foot/toe joint where the
    # content's is, every frame
    feet = root_motion.foot_joints(out.skeleton)
    np.testing.assert_allclose(kinematics.forward_kinematics(out)[:, feet, 1].min(axis=1),
                               kinematics.forward_kinematics(content)[:, feet, 1].min(axis=1), atol=1e-6)


def test_transfer_is_deterministic_and_soft_differs_from_content(trained, model):
    data, _, _ = trained
    content, style = (bvh.load(p) for p in _clips(data)[:2])
    a = model.transfer(content, style)
    b = model.transfer(content, style)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    assert not np.allclose(a.rotations, content.rotations, atol=1e-3)


def test_transfer_other_rate_and_rig(trained, model, bandai_dir, zeggs_dir):
    data, _, _ = trained
    style = bvh.load(_clips(data)[0])
    for path in (bandai_dir / "dataset-1_bow_active_001.bvh", zeggs_dir / "067_Speech_2_x_1_0.bvh"):
        content = bvh.load(path)
        content = datasets.slice_motion(content, 0, min(200, content.num_frames))
        out = model.transfer(content, style, method="soft")
        assert out.num_frames == content.num_frames and out.fps == content.fps
        assert out.skeleton.names == content.skeleton.names
        # the output's lowest foot joint stays where the content's is (not at height 0) on contact frames
        from jaxgest.tgst.api import foot_names

        feet = [content.skeleton.index(n) for n in foot_names(content.skeleton)]
        up = content.skeleton.up_axis
        c_low = kinematics.forward_kinematics(content)[:, feet, up].min(axis=1)
        o_low = kinematics.forward_kinematics(out)[:, feet, up].min(axis=1)
        contact = c_low < c_low.min() + 1.0
        assert np.abs(o_low - c_low)[contact].max() < 1.0
        if path.name.startswith("dataset-1"):
            assert c_low[contact].mean() > 3.0  # Bandai-Namco's foot joints stand ~4 cm above the floor


def test_too_short_and_nan_clips_rejected(trained, model):
    data, _, _ = trained
    content = bvh.load(_clips(data)[0])
    short = datasets.slice_motion(content, 0, 10)
    with pytest.raises(DataError, match="too short"):
        model.transfer(short, content)
    bad = content.replace(rotations=np.where(np.arange(content.num_frames)[:, None, None] == 3, np.nan,
                                             content.rotations))
    with pytest.raises(DataError, match="NaN"):
        model.transfer(content, bad)
    with pytest.raises(DataError, match="unknown transfer method"):
        model.transfer(content, content, method="fancy")


def test_resample_body_round_trip():
    from jaxgest.tgst.api import resample_body

    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(scale=0.01, size=(61, 39)), axis=0)
    same = resample_body(x, 60.0, 60.0, 61)
    np.testing.assert_allclose(same, x, atol=1e-6)
    half = resample_body(x, 60.0, 30.0, 31)
    np.testing.assert_allclose(half, x[::2], atol=1e-6)


def test_cli_transfer_and_evaluate(trained, tmp_path, capsys):
    data, work, _ = trained
    c, s = _clips(data)[:2]
    out = tmp_path / "o.bvh"
    assert cli.main(["tgst", "transfer", "--workdir", str(work), "--content", str(c), "--style", str(s),
                     "--out", str(out), "--method", "adain"]) == 0
    m = bvh.load(out)
    assert m.num_frames == bvh.load(c).num_frames
    report = tmp_path / "r.json"
    assert cli.main(["tgst", "evaluate", "--workdir", str(work), "--data", str(data), "--json", str(report),
                     "--pairs", "all", "--max-pairs", "2", "--methods", "soft,adain"]) == 0
    r = json.loads(report.read_text())
    assert r["num_pairs"] == 2 and set(r["methods"]) == {"soft", "adain"}
    assert r["methods"]["soft"]["num_evaluated"] + r["methods"]["soft"]["num_skipped"] == 2
    capsys.readouterr()


def test_cli_errors_are_one_line(trained, tmp_path, capsys):
    data, work, _ = trained
    c = str(_clips(data)[0])
    cases = [
        ["tgst", "transfer", "--workdir", str(tmp_path / "none"), "--content", c, "--style", c, "--out",
         str(tmp_path / "o.bvh")],
        ["tgst", "transfer", "--workdir", str(work), "--content", c, "--style", c, "--out",
         str(tmp_path / "missing" / "o.bvh")],
        ["tgst", "transfer", "--workdir", str(work), "--content", str(tmp_path / "nope.bvh"), "--style", c,
         "--out", str(tmp_path / "o.bvh")],
    ]
    for argv in cases:
        assert cli.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("jaxgest: ") and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "o.bvh").exists()


def test_a_loaded_model_owns_its_compiled_functions_and_takes_paths(trained, tmp_path):
    """load() reads the workdir on every call; each model keeps its own jit per method (no module-level
    cache), reused by later transfers; transfer takes BVH paths as well as Motions."""
    from jaxgest.tgst.api import load

    data, work, _ = trained
    model = load(work)
    other = load(work)
    assert model is not other and model.steps == {"autoencoder": 4, "transformer": 4}
    assert model.compiled("soft") is model.compiled("soft")
    assert model.compiled("soft") is not other.compiled("soft") and model.compiled("hard") is not model.compiled("soft")
    clips = sorted(data.glob("*.bvh"))[:2]
    from_paths = model.transfer(clips[0], str(clips[1]), method="soft")
    from_motions = model.transfer(bvh.load(clips[0]), bvh.load(clips[1]), method="soft")
    np.testing.assert_array_equal(from_paths.rotations, from_motions.rotations)
    with pytest.raises(DataError, match="style: expected a Motion or a BVH path, got int"):
        model.transfer(clips[0], 3)


def _legacy_flat(cfg) -> dict:
    """The flat config dict the versions before the model/train/inference split stored."""
    from jaxgest.tgst.config import _LEGACY_TRAIN

    flat = {"name": cfg.name, **cfg.model.to_dict()}
    for old, (stage, field) in _LEGACY_TRAIN.items():
        flat[old] = getattr(getattr(cfg.train, stage), field)
    return flat


def test_a_workdir_of_the_flat_config_layout_still_transfers(trained, model, tmp_path):
    """config.json and both checkpoints in the layout before the split ("kind", one flat config) load and
    transfer exactly like the same weights in the new layout."""
    import optax

    from jaxgest.tgst import workdir as W
    from jaxgest.tgst.api import load_model
    from jaxgest.runtime.training import Checkpointer, TrainState, write_json_atomic

    data, work, _ = trained
    old = tmp_path / "old"
    old.mkdir()
    stored = json.loads((work / "config.json").read_text())
    flat = _legacy_flat(model.config)
    del flat["swap_similarity"]  # a field added later: absent in the oldest workdirs (default "dot")
    legacy = {k: v for k, v in stored.items() if k not in ("model", "config")}
    write_json_atomic(old / "config.json", {**legacy, "kind": "tgst", "config": flat})
    for sub, kind, params, extra in ((W.AE_SUBDIR, W.AE_KIND, model.params["autoencoder"], {}),
                                     (W.TRANSFORMER_SUBDIR, W.TRANSFORMER_KIND, model.params["transformer"],
                                      {"autoencoder_step": 4})):
        state = TrainState.create(apply_fn=None, params=params, tx=optax.adam(1e-3))
        with Checkpointer(old, kind=kind, config={**flat, **extra}, skeleton=stored["skeleton"], subdir=sub) as ck:
            ck.save(state.replace(step=4))
    loaded = load_model(old)
    # training fields added after the split (expmap_branch, the step counts) take their defaults (what the
    # version that wrote them did); they only shape training, so the transfer below is unaffected
    tr, defaults = model.config.train, type(model.config.train)()
    assert loaded.cfg == model.cfg and loaded.config.train == dataclasses.replace(
        tr, autoencoder=dataclasses.replace(tr.autoencoder, expmap_branch="principal",
                                            steps=defaults.autoencoder.steps),
        transformer=dataclasses.replace(tr.transformer, steps=defaults.transformer.steps))
    content, style = (bvh.load(p) for p in _clips(data)[:2])
    a, b = loaded.transfer(content, style), model.transfer(content, style)
    np.testing.assert_allclose(a.rotations, b.rotations, atol=1e-6)


def test_training_the_autoencoder_further_retrains_a_stale_transformer(trained, tmp_path):
    """Raising --ae-steps on a finished workdir: the transformer trained on the old autoencoder is kept under
    another name (nothing lost) and a fresh one is trained on the new autoencoder."""
    import shutil

    from jaxgest.tgst.trainer import format_summary, train

    data, work0, _ = trained
    work = tmp_path / "w"
    shutil.copytree(work0, work)
    s = train(data, work, preset="tiny", ae_steps=5, transformer_steps=2, progress=False, log_every=1, ckpt_every=1)
    assert s["ae"]["start_step"] == 4 and s["ae"]["steps"] == 5
    assert s["transformer"]["start_step"] == 0 and s["transformer"]["steps"] == 2
    assert s["stale_transformer"] == "transformer.autoencoder-step-4"
    assert (work / "checkpoints" / "transformer.autoencoder-step-4").is_dir()
    assert "was moved to checkpoints/transformer.autoencoder-step-4 and retrained" in format_summary(s)
    again = train(data, work, preset="tiny", ae_steps=5, transformer_steps=2, progress=False)
    assert again["stale_transformer"] is None
    assert "autoencoder already at step 5, nothing to do; transformer already at step 2" in format_summary(again)


def test_output_keeps_the_contents_floor_contact_height(trained, model):
    """The content stands with its foot joints 4.25 cm above the floor and leaves the floor for a while (a
    jump): by default (paper §3.1) the output's lowest foot joint is where the content's is on every frame,
    in the air too, instead of sinking to height 0; with the tube contact (tolerance 0.9 cm) it stays within
    the tolerance on every contact frame and in the air the root's shift is the line between them."""
    from jaxgest.tgst import api

    data, _, _ = trained
    content, style = (bvh.load(p) for p in _clips(data)[:2])
    F = content.num_frames
    jump = np.where((np.arange(F) > 60) & (np.arange(F) < 90), 20.0 * np.sin(np.pi * (np.arange(F) - 60) / 30), 0.0)
    lift = 4.25 + jump  # cm above the original per-frame height
    hips = kinematics.forward_kinematics(content)[:, 0]
    raised = root_motion.set_root_position(content, hips + lift[:, None] * np.array([0.0, 1.0, 0.0]))
    feet = root_motion.foot_joints(content.skeleton)
    c_low = kinematics.forward_kinematics(raised)[:, feet, 1].min(axis=1)
    contact = c_low < c_low.min() + 1.0  # frames where the content's lowest foot is at its contact height
    assert contact.sum() > F // 2 and (~contact).sum() >= 20 and c_low.min() > 4.0
    out = model.transfer(raised, style, method="soft")
    o_low = kinematics.forward_kinematics(out)[:, feet, 1].min(axis=1)
    np.testing.assert_allclose(o_low, c_low, atol=1e-6)  # SPEC §3.1: per frame, flight included
    assert api.CONTACT_TOLERANCE == 0.0
    tube = model.transfer(raised, style, method="soft", tolerance=0.9)
    t_low = kinematics.forward_kinematics(tube)[:, feet, 1].min(axis=1)
    assert np.abs(t_low - c_low)[contact].max() <= 0.9 + 1e-6
    h = kinematics._hips_index(content.skeleton)
    d = kinematics.forward_kinematics(tube)[:, h, 1] - kinematics.forward_kinematics(raised)[:, h, 1]
    on = np.flatnonzero(contact)  # in the air: the root's shift is the line between the contact frames'
    np.testing.assert_allclose(d, np.interp(np.arange(F), on, d[on]), atol=1e-6)


@pytest.mark.slow
def test_batched_transfer_equals_model_transfer_and_reports_swap_weights(trained, model):
    """jaxgest.tgst.evaluate's in-process transfers: exact shapes give model.transfer's result; buckets pad
    the clips (their own first frames again) and cut the result back to the content's frames."""
    from jaxgest.motion.datasets import Clip
    from jaxgest.tgst import evaluate as ev

    data, _, _ = trained
    content, style = (bvh.load(p) for p in _clips(data)[:2])
    pair = ev.Pair(Clip(content, "c", "neutral", None), Clip(style, "s", "sad", None))
    exact, diag = ev.BatchedTransfer(model, ("soft",), ratio=1.0).run(pair)
    direct = model.transfer(content, style, method="soft", style_input="as-is")  # what the pair gives
    np.testing.assert_allclose(exact["soft"].rotations, direct.rotations, atol=2e-5)
    np.testing.assert_allclose(exact["soft"].translations, direct.translations, atol=1e-3)
    assert 0 < diag["max_weight"] <= 1 and 1 <= diag["effective_tokens"] <= diag["num_style"]
    frames = style.num_frames  # 60 fps: the model's rate
    assert model.cfg.edge_frames  # the swap pool: tokens of the real style latents, ceil(ceil(F / 4) / 2) - 1
    assert diag["num_style"] == -(-(-(-frames // 4)) // 2) - 1 and diag["num_queries"] > 0
    assert 0 <= diag["chance_within_1"] <= 3 / diag["num_style"] and diag["padding_mass"] == 0.0
    bucketed, bdiag = ev.BatchedTransfer(model, ("soft",), ratio=1.5).run(pair)
    assert ev.bucket_length(frames, 1.5) > frames  # really padded
    assert bucketed["soft"].num_frames == content.num_frames
    # issue 58: the padding is masked (no weight, no attention), so the bucketed transfer is the exact one
    np.testing.assert_allclose(bucketed["soft"].rotations, exact["soft"].rotations, atol=2e-5)
    assert bdiag["num_style"] == diag["num_style"] and bdiag["padding_mass"] == 0.0
    assert bdiag["max_weight"] == pytest.approx(diag["max_weight"], abs=1e-5)


@pytest.mark.slow
def test_cli_transfer_equals_the_experiments_path(trained, tmp_path, capsys):
    """Issue 58: ``jaxgest tgst transfer`` gives the model the style input of the experiments' results (the
    exemplar followed by its mirror) by default, and ``--style-input as-is`` the exemplar itself: the CLI's
    output scores what the multi-take evaluation (experiments/tgst_bandai2) scores for the same pair and
    input, for the soft and the coherent swap."""
    from jaxgest.motion.datasets import Clip
    from jaxgest.tgst import multitake_eval as me
    from jaxgest.tgst.api import load_model
    from jaxgest.tgst.multitake import TakePair
    from jaxgest.tgst.protocol import clip_features

    data, work, _ = trained
    c_path, s_path = _clips(data)[:2]
    content, exemplar = bvh.load(c_path), bvh.load(s_path)
    pair = TakePair("inter-other", Clip(content, "c", "neutral", c_path), Clip(exemplar, "s", "sad", s_path), ())
    proto = me.multitake_protocol()
    report = me.evaluate_pairs(load_model(work), [pair], protocol=proto, methods=("soft", "coherent"),
                               oracle_every=0, controls=False)
    rows = report["pairs"][0]["rows"]
    fps, window = content.fps, me.window_frames(content.fps)
    feats = me.FeatureCache(proto, fps)
    scored = {}
    for method in ("soft", "coherent"):
        for flag, variant in (([], "mirror"), (["--style-input", "as-is"], "as_is")):
            out = tmp_path / f"{method}_{variant}.bvh"
            assert cli.main(["tgst", "transfer", "--workdir", str(work), "--content", str(c_path), "--style",
                             str(s_path), "--out", str(out), "--method", method, *flag]) == 0
            got = me.errors_against(clip_features(bvh.load(out), fps, proto), feats(pair.content),
                                    feats(pair.exemplar, True), [], window=window)
            want = rows[f"{method}|{variant}"]
            for k in ("content", "style"):
                assert got[k] == pytest.approx(want[k], rel=1e-3, abs=1e-4), (method, variant, k)
            scored[method, variant] = got
    # control: the two inputs give different transfers, so the match above tells which input the CLI used
    assert abs(scored["soft", "mirror"]["style"] - scored["soft", "as_is"]["style"]) > 1e-3
    capsys.readouterr()

"""jaxgest runs the ZeroEGGS authors' networks as they do: parity with their own code, executed.

The authors' code and released files are read where they lie (``../shared/third_party/zeggs-official``,
:mod:`authors_zeggs`); the released decoder and style encoder are not there (Git LFS), so those two are the
authors' own module classes with random weights, saved as the authors save them (``torch.save(module)``),
imported through ``jaxgest zeggs import-official`` and run on the same inputs. Tolerances (float32 on both
sides, different summation orders):

* features (``preprocess_animation``): 1e-5 of each feature's largest value -- the same formulas, but their
  BVH reader and 2-axis arrays are float32 (measured: 2e-6 cm on positions, 4e-6 relative on velocities);
* style encoder ``(mu, logvar)``: 1e-4 of the largest value (measured 6e-7 of 4.3);
* decoder over 300 generated frames: positions within 1e-4 cm, 2-axis rotations and root rotation within
  1e-5 (measured: 8e-6 cm on local positions, 3e-6 cm on the root, 3e-7 on the 2-axis rotations).
"""

from __future__ import annotations

import json
import os
import pathlib
import shutil

import numpy as np
import pytest

from authors_zeggs import OFFICIAL, ZEGGS_CODE, authors_code, released, require_authors, their

ZEGGS_BVH = OFFICIAL.parents[1] / "data" / "speech-gesture" / "zeggs" / "067_Speech_2_x_1_0.bvh"
HIDDEN = 128  # decoder / style encoder width of the random-weight test networks (the release's: 1024 / 512)


def _bvh_60fps(src: pathlib.Path, dst: pathlib.Path, frames: int) -> pathlib.Path:
    """The first ``frames`` frames of a 30 fps BVH at 60 fps, each frame repeated (the authors' code asserts
    60 fps examples)."""
    text = src.read_text().splitlines()
    i = next(k for k, line in enumerate(text) if line.startswith("Frames:"))
    rows = text[i + 2:i + 2 + frames // 2]
    body = [r for r in rows for _ in range(2)]
    dst.write_text("\n".join(text[:i] + [f"Frames: {len(body)}", "Frame Time: 0.0166667"] + body) + "\n")
    return dst


def _randomize(module, seed: int) -> None:
    import torch

    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in module.named_parameters():
            if p.ndim == 1:
                base = 1.0 if name.endswith("weight") else 0.0  # LayerNorm gains near 1, biases near 0
                p.copy_(base + 0.1 * torch.randn(p.shape, generator=g))
            else:
                fan_in = int(np.prod(p.shape[1:]))
                p.copy_(torch.randn(p.shape, generator=g) / np.sqrt(fan_in))


@pytest.fixture(scope="module")
def release_repo(tmp_path_factory):
    """A clone-shaped folder of the authors' repository: the real v1 speech encoder, stats and definitions,
    random-weight decoder and style encoder of the authors' classes (width :data:`HIDDEN`)."""
    require_authors()
    if not ZEGGS_BVH.is_file():
        pytest.skip(f"no shared ZEGGS clip at {ZEGGS_BVH}")
    import torch

    root = tmp_path_factory.mktemp("zeggs_repo")
    out = root / "data" / "outputs" / "v1"
    (out / "saved_models").mkdir(parents=True)
    data = root / "data" / "processed_v1"
    data.mkdir(parents=True)
    for name in ("stats.npz", "data_definition.json", "data_pipeline_conf.json"):
        shutil.copy(released("v1", name), data / name)
    shutil.copy(released("v1", "speech_encoder.pt"), out / "saved_models" / "speech_encoder.pt")
    os.symlink(ZEGGS_CODE, root / "ZEGGS")
    options = json.loads(released("v1", "options.json").read_text())
    options["net_opt"]["decoder"]["nhidden"] = HIDDEN
    options["net_opt"]["style_encoder"]["nhidden"] = HIDDEN
    (out / "options.json").write_text(json.dumps(options))
    with authors_code():
        modules = their("modules")
        torch.manual_seed(0)
        dec = modules.Decoder(pose_input_size=1134, pose_output_size=1131, speech_encoding_size=64,
                              style_encoding_size=64, hidden_size=HIDDEN, num_rnn_layers=2)
        sty = modules.StyleEncoder(1134, HIDDEN, 64, type="attn", use_vae=True)
        _randomize(dec, 1)
        _randomize(sty, 2)
        torch.save(dec, out / "saved_models" / "decoder.pt")
        torch.save(sty, out / "saved_models" / "style_encoder.pt")
    clip = _bvh_60fps(ZEGGS_BVH, root / "example.bvh", 600)
    return root, clip


@pytest.fixture(scope="module")
def imported(release_repo, tmp_path_factory):
    from jaxgest.zeggs.official import import_release, load

    repo, _ = release_repo
    w = tmp_path_factory.mktemp("official_w") / "w"
    import_release(repo, "v1", w, log=lambda *_: None)
    return load(w)


def _their_features(path):
    with authors_code():
        anim = their("anim.bvh").load(str(path))
        return their("data_pipeline").preprocess_animation(anim)


def test_features_equal_the_authors_preprocess_animation(release_repo):
    from jaxgest.motion import bvh
    from jaxgest.zeggs.official import features

    _, clip = release_repo
    names = ("root_pos", "root_rot", "root_vel", "root_vrt", "lpos", "lrot", "ltxy", "lvel", "lvrt")
    theirs = dict(zip(names, _their_features(clip)[:9]))
    theirs["gaze_pos"], theirs["gaze_dir"] = _their_features(clip)[14:16]
    mine = features.pose_state(bvh.load(clip))
    for k in theirs:
        a, b = np.asarray(theirs[k], np.float64), mine[k]
        if k == "lrot":  # q and -q are one rotation; their unroll starts from their Euler conversion's sign
            a = a * np.sign(np.sum(a * b, axis=-1, keepdims=True))
        assert b.shape == a.shape, k
        assert np.abs(b - a).max() <= 1e-5 * np.abs(a).max(), (k, np.abs(b - a).max(), np.abs(a).max())


def test_style_encoder_equals_theirs(release_repo, imported):
    import torch

    from jaxgest.motion import bvh

    repo, clip = release_repo
    x = imported.style_input(bvh.load(clip))[:300]
    with authors_code():
        sty = torch.load(repo / "data/outputs/v1/saved_models/style_encoder.pt", map_location="cpu").eval()
        with torch.no_grad():
            _, mu, logvar = sty(torch.as_tensor(x)[None], 1.0)
    m, lv = imported._style(imported.params["style_encoder"], x[None])
    scale = float(np.abs(mu.numpy()).max() + np.abs(logvar.numpy()).max())
    assert np.abs(np.asarray(m) - mu.numpy()).max() <= 1e-4 * scale
    assert np.abs(np.asarray(lv) - logvar.numpy()).max() <= 1e-4 * scale


def test_decoder_over_300_frames_equals_theirs(release_repo, imported):
    import torch

    from jaxgest.motion import bvh
    from jaxgest.zeggs.official import features, network

    repo, clip = release_repo
    T = 300
    rng = np.random.default_rng(0)
    speech = rng.normal(size=(1, T, 64)).astype(np.float32) * 0.5
    style = rng.normal(size=(1, T, 64)).astype(np.float32)
    st = features.pose_state(bvh.load(clip))
    stats = {k: torch.as_tensor(v) for k, v in imported.release.stats.items()}
    with authors_code():
        dec = torch.load(repo / "data/outputs/v1/saved_models/decoder.pt", map_location="cpu").eval()
        t = {k: torch.as_tensor(np.asarray(st[k][:1], np.float32)) for k in network.STATE_KEYS}
        gaze = torch.as_tensor(np.asarray(st["gaze_pos"][:1], np.float32)).repeat_interleave(T, 0)[None]
        with torch.no_grad():
            outs = dec(t["root_pos"], t["root_rot"], t["root_vel"], t["root_vrt"], t["lpos"], t["ltxy"],
                       t["lvel"], t["lvrt"], gaze, torch.as_tensor(speech), torch.as_tensor(style),
                       torch.as_tensor(np.asarray(imported.release.manifest["parents"])),
                       stats["anim_input_mean"], stats["anim_input_std"], stats["anim_output_mean"],
                       stats["anim_output_std"], imported.dt)
    theirs = dict(zip(network.STATE_KEYS, (o.numpy() for o in outs)))
    state0 = {k: np.asarray(st[k][:1], np.float32) for k in network.STATE_KEYS}
    mine = imported._decoder(imported.params["decoder"], state0, gaze.numpy(), speech, style, imported.stats)
    assert theirs["lpos"].shape == (1, T, 75, 3)
    assert np.abs(theirs["lpos"][0, -1] - theirs["lpos"][0, 1]).max() > 1.0  # the output moves
    np.testing.assert_allclose(np.asarray(mine["lpos"]), theirs["lpos"], atol=1e-4, rtol=0)
    np.testing.assert_allclose(np.asarray(mine["ltxy"]), theirs["ltxy"], atol=1e-5, rtol=0)
    np.testing.assert_allclose(np.asarray(mine["root_pos"]), theirs["root_pos"], atol=1e-4, rtol=0)
    np.testing.assert_allclose(np.asarray(mine["root_rot"]), theirs["root_rot"], atol=1e-5, rtol=0)


def test_import_names_the_missing_or_mismatched_file(release_repo, tmp_path):
    from jaxgest.runtime.errors import DataError
    from jaxgest.zeggs.official import import_release

    repo, _ = release_repo
    broken = tmp_path / "repo"
    shutil.copytree(repo, broken, symlinks=True)
    (broken / "data/outputs/v1/saved_models/decoder.pt").unlink()
    with pytest.raises(DataError, match=r"decoder\.pt: missing"):
        import_release(broken, "v1", tmp_path / "w1", log=lambda *_: None)
    assert not (tmp_path / "w1" / "official.json").exists()
    (broken / "data/outputs/v1/saved_models/decoder.pt").write_text("version https://git-lfs.github.com/spec/v1\n")
    with pytest.raises(DataError, match="Git LFS pointer"):
        import_release(broken, "v1", tmp_path / "w2", log=lambda *_: None)
    shutil.copy(repo / "data/outputs/v1/saved_models/decoder.pt", broken / "data/outputs/v1/saved_models/decoder.pt")
    opts = json.loads((broken / "data/outputs/v1/options.json").read_text())
    opts["net_opt"]["decoder"]["nhidden"] = HIDDEN * 2
    (broken / "data/outputs/v1/options.json").write_text(json.dumps(opts))
    with pytest.raises(DataError, match=r"decoder\.pt: .* has shape"):
        import_release(broken, "v1", tmp_path / "w3", log=lambda *_: None)
    with pytest.raises(DataError, match="--version must be one of"):
        import_release(repo, "v3", tmp_path / "w4", log=lambda *_: None)


# -- the whole pipeline against the authors' generate.py --------------------------------------------------
ZEGGS_WAV = ZEGGS_BVH.with_suffix(".wav")
SECONDS = 12.0


@pytest.fixture(scope="module")
def speech_wav(tmp_path_factory):
    """The first 12 s of the shared ZEGGS speech (its own sample rate)."""
    import soundfile as sf

    if not ZEGGS_WAV.is_file():
        pytest.skip(f"no shared ZEGGS speech at {ZEGGS_WAV}")
    y, sr = sf.read(str(ZEGGS_WAV), dtype="float32")
    path = tmp_path_factory.mktemp("speech") / "speech12.wav"
    sf.write(str(path), y[: int(SECONDS * sr)], sr)
    return path


def _their_generate(repo, results, **kw):
    import pathlib as pl

    with authors_code():
        gen = their("generate")
        gen.generate_gesture(network_path=pl.Path(repo) / "data/outputs/v1/saved_models",
                             data_path=pl.Path(repo) / "data/processed_v1", results_path=pl.Path(results),
                             use_gpu=False, file_name="theirs", **kw)
    return pl.Path(results) / "theirs.bvh"


def _world(motion) -> np.ndarray:
    from jaxgest.motion.kinematics import forward_kinematics

    return forward_kinematics(motion)


def test_cli_generate_at_temperature_0_equals_the_authors_generate_gesture(release_repo, speech_wav, tmp_path,
                                                                           capsys):
    """Done-when of the import: ``import-official`` + ``zeggs generate --temperature 0`` (the posterior mean)
    matches ``generate_gesture`` at temperature 1e9 (theirs divides sigma) over 12 s of speech. The issue's
    bar is 1 cm max / 0.1 cm mean joint position; measured 0.0057 cm max / 0.0012 cm mean (float32 on both
    sides and their BVH text at 6 decimals), so the test holds it to 0.05 / 0.01 cm."""
    from jaxgest.cli import main
    from jaxgest.motion import bvh

    repo, clip = release_repo
    w, out = tmp_path / "w", tmp_path / "mine.bvh"
    assert main(["zeggs", "import-official", "--repo", str(repo), "--version", "v1", "--workdir", str(w)]) == 0
    assert main(["zeggs", "generate", "--workdir", str(w), "--audio", str(speech_wav), "--style", str(clip),
                 "--temperature", "0", "--out", str(out)]) == 0
    theirs = bvh.load(_their_generate(repo, tmp_path / "theirs", audio_file=speech_wav, styles=[(clip, None)],
                                      temperature=1e9))
    mine = bvh.load(out)
    assert mine.num_frames == theirs.num_frames == int(round(60 * SECONDS))
    err = np.linalg.norm(_world(mine) - _world(theirs), axis=-1)
    motion = np.linalg.norm(_world(theirs)[1:] - _world(theirs)[:-1], axis=-1).sum(0).max()
    assert motion > 10.0  # some joint travels more than 10 cm: the comparison is not of two still poses
    assert err.max() <= 0.05 and err.mean() <= 0.01, (err.max(), err.mean())


def test_label_based_v2_generates_from_a_label_and_a_first_pose(release_repo, speech_wav, tmp_path):
    """v2 has no style encoder: a label's one-hot vector and a first pose (theirs requires one). Measured
    against their ``generate_gesture``: 0.0060 cm max / 0.0014 cm mean over 12 s."""
    import torch

    from jaxgest.motion import bvh
    from jaxgest.runtime.errors import JaxgestError
    from jaxgest.zeggs.official import import_release, load

    repo, clip = release_repo
    v2 = tmp_path / "repo2"
    shutil.copytree(repo, v2, symlinks=True)
    (v2 / "data/outputs/v1/saved_models/style_encoder.pt").unlink()
    opts = json.loads((v2 / "data/outputs/v1/options.json").read_text())
    opts["train_opt"]["style_encoding_type"] = "label"
    (v2 / "data/outputs/v1/options.json").write_text(json.dumps(opts))
    labels = json.loads((v2 / "data/processed_v1/data_definition.json").read_text())["label_names"]
    with authors_code():
        dec = their("modules").Decoder(pose_input_size=1134, pose_output_size=1131, speech_encoding_size=64,
                                       style_encoding_size=len(labels), hidden_size=HIDDEN, num_rnn_layers=2)
        _randomize(dec, 3)
        torch.save(dec, v2 / "data/outputs/v1/saved_models/decoder.pt")
    import_release(v2, "v1", tmp_path / "w", log=lambda *_: None)
    model = load(tmp_path / "w")
    with pytest.raises(JaxgestError, match="needs a first pose"):
        model.generate(speech_wav, [labels[0]])
    with pytest.raises(JaxgestError, match="styles must be among"):
        model.generate(speech_wav, ["NoSuchStyle"], first_pose=clip)
    mine = model.generate(speech_wav, [labels[0]], first_pose=clip)
    theirs = bvh.load(_their_generate(v2, tmp_path / "theirs", audio_file=speech_wav, styles=[labels[0]],
                                      style_encoding_type="label", first_pose=clip))
    err = np.linalg.norm(_world(mine) - _world(theirs), axis=-1)
    assert err.max() <= 0.05 and err.mean() <= 0.01, (err.max(), err.mean())


# -- the training objective against the loss block of their train.py, executed --------------------------------
def _their_loss_block() -> str:
    """The lines of their ``train.py`` from ``# Compute Character/World Space`` to ``) / 18.0`` (read where
    they lie, dedented; executed as they are)."""
    import textwrap

    lines = (ZEGGS_CODE / "train.py").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if "# Compute Character/World Space" in line)
    end = next(i for i, line in enumerate(lines) if i > start and line.strip().startswith(") / 18.0"))
    return textwrap.dedent("\n".join(lines[start:end + 1]))


@pytest.mark.parametrize("error", ["shift", "noise", "static"])
def test_loss_terms_equal_their_train_py(release_repo, error):
    """Every weighted term, the KL and the total on the same errors as their train.py: a 0.15 s shift of the
    real clip, noise on every channel, and a static pose (their scale: the issue measured 2.2-4.5)."""
    import torch

    from jaxgest.motion import bvh
    from jaxgest.zeggs.official import features, losses, network

    _, clip = release_repo
    st = features.pose_state(bvh.load(clip))
    T, B, shift = 64, 2, 9  # 0.15 s at 60 fps
    W = {k: np.stack([st[k][s:s + T] for s in (100, 300)]).astype(np.float32) for k in network.STATE_KEYS}
    if error == "shift":
        O = {k: np.stack([st[k][s + shift:s + shift + T] for s in (100, 300)]).astype(np.float32) for k in W}
    elif error == "noise":
        rng = np.random.default_rng(1)
        O = {k: (v + rng.normal(scale=0.05 * (np.abs(v).mean() + 1e-3), size=v.shape)).astype(np.float32)
             for k, v in W.items()}
        O["root_rot"] = O["root_rot"] / np.linalg.norm(O["root_rot"], axis=-1, keepdims=True)
    else:
        O = {k: np.repeat(v[:, :1], T, axis=1) for k, v in W.items()}
    gaze = np.stack([st["gaze_pos"][s:s + T] for s in (100, 300)]).astype(np.float32)
    rng = np.random.default_rng(2)
    mu, logvar = rng.normal(size=(B, 64)).astype(np.float32), rng.normal(size=(B, 64)).astype(np.float32) * 0.3
    iteration, dt = 9000, 1.0 / 60.0
    parents = [int(p) for p in bvh.load(clip).skeleton.parents]
    with authors_code():
        ns = {}
        for m in ("anim.tquat", "anim.txform", "modules"):
            ns.update({k: v for k, v in vars(their(m)).items() if not k.startswith("__")})
        ns.update({"torch": torch, "dt": dt, "iteration": iteration, "parents": torch.as_tensor(parents),
                   "mu": torch.as_tensor(mu), "logvar": torch.as_tensor(logvar), "W_gaze_pos": torch.as_tensor(gaze)})
        names = {"root_pos": "root_pos", "root_rot": "root_rot", "root_vel": "root_vel", "root_vrt": "root_vrt",
                 "lpos": "lpos", "ltxy": "ltxy", "lvel": "lvel", "lvrt": "lvrt"}
        for k, n in names.items():
            ns[f"O_{n}"], ns[f"W_{n}"] = torch.as_tensor(O[k]), torch.as_tensor(W[k])
        exec(compile(_their_loss_block(), str(ZEGGS_CODE / "train.py"), "exec"), ns)
    terms = losses.reconstruction_terms({k: O[k] for k in O}, {k: W[k] for k in W}, gaze, parents, dt)
    kl = losses.kl_divergence(mu, logvar)
    total = float(losses.total_loss(terms, kl, iteration))
    for k in losses.WEIGHTS:
        theirs = float(ns[f"loss_{k}"])
        assert abs(float(terms[k]) - theirs) <= 1e-4 * max(abs(theirs), 1e-3), (k, float(terms[k]), theirs)
    assert abs(float(losses.kl_weight(iteration) * kl) - float(ns["loss_kl_div"])) <= 1e-5
    assert abs(total - float(ns["loss"])) <= 1e-4 * abs(float(ns["loss"]))
    if error != "noise":  # measured: 5.8 (shift), 4.6 (static); jaxgest's root-frame terms read 39-66 here
        assert 1.0 < float(sum(terms[k] for k in losses.WEIGHTS)) < 20.0

"""Training the ZeroEGGS authors' network in JAX (``jaxgest zeggs train --preset authors-tiny``).

The parameters have the names and shapes of their modules' ``state_dict()``, the style encoder gives a padded
(masked) example exactly what it gives the example alone, the batches are a pure function of (seed, step), a
killed run resumes to the parameters of an uninterrupted one, and ``zeggs generate`` reads the workdir.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from authors_zeggs import authors_code, their


def _options():
    from jaxgest.zeggs.official.train import options_for

    return options_for("authors-tiny")


def test_parameters_have_their_modules_names_and_shapes():
    import torch  # noqa: F401 -- their modules need it

    from jaxgest.zeggs.official.train import param_shapes

    o = _options()
    net = o["net_opt"]
    J = 21
    with authors_code():
        m = their("modules")
        mods = {
            "speech_encoder": m.SpeechEncoder(81, net["speech_encoder"]["nhidden"],
                                              net["speech_encoder"]["speech_encoding_size"]),
            "decoder": m.Decoder(pose_input_size=9 + 15 * J, pose_output_size=6 + 15 * J,
                                 speech_encoding_size=net["speech_encoder"]["speech_encoding_size"],
                                 style_encoding_size=net["style_encoder"]["style_encoding_size"],
                                 hidden_size=net["decoder"]["nhidden"], num_rnn_layers=2),
            "style_encoder": m.StyleEncoder(9 + 15 * J, net["style_encoder"]["nhidden"],
                                            net["style_encoder"]["style_encoding_size"], type="attn", use_vae=True),
        }
        theirs = {k: {n: tuple(v.shape) for n, v in mod.state_dict().items()} for k, mod in mods.items()}
    assert param_shapes(o, J) == theirs


def test_masked_style_encoder_gives_each_example_what_it_gets_alone():
    from jaxgest.zeggs.official import network
    from jaxgest.zeggs.official.train import init_params

    p = init_params(_options(), 4, jax.random.key(0))["style_encoder"]
    rng = np.random.default_rng(0)
    P = 9 + 15 * 4
    a, b = rng.normal(size=(1, 37, P)).astype(np.float32), rng.normal(size=(1, 52, P)).astype(np.float32)
    padded = np.zeros((2, 64, P), np.float32)
    padded[0, :37], padded[1, :52] = a[0], b[0]
    mask = np.zeros((2, 64), bool)
    mask[0, :37], mask[1, :52] = True, True
    mu, lv = network.style_encoder(p, jnp.asarray(padded), mask=jnp.asarray(mask))
    for i, x in enumerate((a, b)):
        m1, l1 = network.style_encoder(p, jnp.asarray(x))
        np.testing.assert_allclose(np.asarray(mu[i]), np.asarray(m1[0]), atol=1e-5)
        np.testing.assert_allclose(np.asarray(lv[i]), np.asarray(l1[0]), atol=1e-5)
    unmasked, _ = network.style_encoder(p, jnp.asarray(padded))  # the control: padding without the mask differs
    assert np.abs(np.asarray(unmasked[0]) - np.asarray(mu[0])).max() > 1e-3


@pytest.fixture(scope="module")
def sequences(tiny_data):
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs.official.train import build_sequences

    return build_sequences([c for c in load_folder(tiny_data) if c.audio is not None])


def test_sequences_statistics_and_batches(sequences):
    from jaxgest.zeggs.official.train import batch

    seq = sequences
    assert len(seq.ranges) == 4 * 2 * 2  # clips x (as is, mirrored) x length ratios (0.9, 1.0)
    s = seq.stats
    assert s["anim_input_mean"].shape == (9 + 15 * 21,) and s["anim_output_std"].shape == (6 + 15 * 21,)
    assert np.ndim(s["audio_input_std"]) == 0 and np.all(np.isfinite(s["anim_input_std"]))
    # one std per group in the input statistics (their data_pipeline), per channel in the output ones
    assert len(np.unique(s["anim_input_std"][6:6 + 3 * 21])) == 1
    assert len(np.unique(s["anim_output_std"][6:6 + 3 * 21])) > 1
    b1 = batch(seq, 7, seed=0, batch_size=3, window=32, example_length=48)
    b2 = batch(seq, 7, seed=0, batch_size=3, window=32, example_length=48)
    b3 = batch(seq, 8, seed=0, batch_size=3, window=32, example_length=48)
    assert all(np.array_equal(b1[k], b2[k]) for k in b1)
    assert not np.array_equal(b1["lpos"], b3["lpos"])
    assert b1["example"].shape == (3, 96, 9 + 15 * 21) and b1["lpos"].shape == (3, 32, 21, 3)
    n = int(b1["example_mask"][0].sum())
    assert 48 <= n <= 96 and n % 2 == 0 and np.all(b1["example_mask"].sum(1) == n)  # one length per step
    assert np.all(b1["example"][:, n:] == 0)


def _train(data, w, steps, **kw):
    from jaxgest.zeggs.official.train import train

    return train(data, w, preset="authors-tiny", steps=steps, progress=False, log_every=1, ckpt_every=2, **kw)


def _params(w):
    from jaxgest.zeggs.official.release import read_workdir

    return read_workdir(w).params


@pytest.mark.slow
def test_train_resumes_to_the_uninterrupted_run_and_generates(tiny_data, tmp_path, capsys):
    from jaxgest.cli import main
    from jaxgest.motion import bvh

    _train(tiny_data, tmp_path / "full", 4)
    _train(tiny_data, tmp_path / "part", 2)
    r = _train(tiny_data, tmp_path / "part", 4)
    assert r["start_step"] == 2
    a, b = _params(tmp_path / "full"), _params(tmp_path / "part")
    for net in a:
        for name in a[net]:
            np.testing.assert_allclose(a[net][name], b[net][name], atol=1e-6, err_msg=f"{net}/{name}")
    lines = [json.loads(x) for x in (tmp_path / "full" / "metrics.jsonl").read_text().splitlines()]
    assert [x["step"] for x in lines] == [1, 2, 3, 4]
    assert all(np.isfinite(x["loss"]) and x["lpos"] > 0 for x in lines)
    clip = sorted(tiny_data.glob("*.bvh"))[0]
    out = tmp_path / "g.bvh"
    assert main(["zeggs", "generate", "--workdir", str(tmp_path / "full"), "--audio", str(clip.with_suffix(".wav")),
                 "--style", str(clip), "--out", str(out)]) == 0
    m = bvh.load(out)
    assert m.fps == 60 and m.skeleton.names == bvh.load(clip).skeleton.names
    assert abs(m.num_frames - round(60 * bvh.load(clip).duration)) <= 2

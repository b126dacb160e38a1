"""The damping diagnostic of experiments/zeggs_synthetic (why the rollout is over-damped): its pieces."""

from __future__ import annotations

import importlib.util
import json
import pathlib

import numpy as np
import pytest

EXP = pathlib.Path(__file__).resolve().parents[2] / "experiments" / "zeggs_synthetic"


def _module(name: str):
    spec = importlib.util.spec_from_file_location(name, EXP / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_lagged_takes_offsets_with_edges_repeated():
    dd = _module("damping_diagnostic")
    x = np.arange(5.0)[:, None] * np.array([[1.0, 10.0]])  # (5, 2)
    out = dd._lagged(x, 1, 2)  # offsets -1, 0, 1, 2 for each of the 2 channels
    assert out.shape == (5, 8)
    # frame 0: x[0] (clamped from -1), x[0], x[1], x[2]
    np.testing.assert_array_equal(out[0].reshape(4, 2)[:, 0], [0, 0, 1, 2])
    # frame 4: x[3], x[4], x[4], x[4] (clamped at the end)
    np.testing.assert_array_equal(out[4].reshape(4, 2)[:, 1], [30, 40, 40, 40])


def test_group_mae_skips_the_given_frame_and_splits_groups():
    dd = _module("damping_diagnostic")
    from jaxgest.zeggs.features import PoseLayout

    lay = PoseLayout(2)
    target = np.zeros((1, 3, lay.size))
    pred = target.copy()
    pred[:, 0] = 100.0  # frame 0 is given: not scored
    pred[:, 1:, lay.local_velocities] = 2.0
    out = dd.group_mae(pred, target, lay)
    assert out["local_velocities"] == pytest.approx(2.0)
    assert out["local_positions"] == 0.0 and out["root_velocity"] == 0.0
    assert out["all"] == pytest.approx(2.0 * 6 / lay.size)


def test_compare_damping_pairs_clips(tmp_path, capsys):
    cd = _module("compare_damping")

    def doc(gen):
        rows = [{"local_velocities": {"1-63": g}, "local_positions": {"1-63": 1.0}} for g in gen]
        real = [{"local_velocities": {"1-63": 2.0}, "local_positions": {"1-63": 1.0}} for _ in gen]
        return {"decay": {"per_clip": {"inference_init": rows, "real": real}}}

    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(doc([0.2, 0.4])))
    b.write_text(json.dumps(doc([0.4, 1.0])))
    np.testing.assert_allclose(cd.ratios(json.loads(b.read_text()), "inference_init", "local_velocities", "1-63"),
                               [0.2, 0.5])
    assert cd.main([str(a), str(b)]) == 0
    line = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("| local_velocities, 1-63")][0]
    assert "+0.200 ± 0.100" in line  # differences 0.1 and 0.3: mean 0.2, SE std(ddof=1) / sqrt(2) = 0.1


def test_loss_part_on_the_tiny_model(zeggs_workdir, tiny_data):
    dd = _module("damping_diagnostic")
    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs.inference import load_model

    model = load_model(zeggs_workdir)
    out = dd.part_loss(model, [c for c in load_folder(tiny_data) if c.audio is not None], batches=1, seed=0)
    assert out["windows"] == model.cfg.train.batch_size
    rec = out["reconstruction_loss"]
    # at 60 fps the previous true frame is far closer to the target than the mean pose or a held frame 0
    assert rec["previous_true_frame"] < rec["hold_frame0"] and rec["previous_true_frame"] < rec["mean_pose"]
    mae = out["mae_group_units"]
    assert mae["previous_true_frame"]["all"] < mae["mean_pose"]["all"]
    assert set(out["reconstruction_minus_model"]) == {"model_e0", "mean_pose", "hold_frame0", "previous_true_frame"}


def test_small_preset_speech_encoder_sees_half_a_second_ahead():
    """The synthetic gestures start up to ~0.9 s before the speech onset they are timed to: with +-8 frames of
    speech (kernels 3, 15) the small model's rollout stayed over-damped. The small preset's speech embedding
    at frame t must depend on the speech ~0.5 s later (and earlier), and not beyond its receptive field."""
    import jax
    import jax.numpy as jnp

    from jaxgest.zeggs.config import preset
    from jaxgest.zeggs.speech_encoder import SpeechEncoder

    cfg = preset("small").model
    reach = sum((k - 1) // 2 for k in cfg.speech_kernels)  # frames seen on each side
    assert reach >= 0.5 * cfg.fps
    enc = SpeechEncoder(cfg)
    x = jax.random.normal(jax.random.key(0), (1, 4 * reach, cfg.speech_dim))
    params = enc.init(jax.random.key(1), x)
    t = reach + 2
    base = enc.apply(params, x)[0, t]
    for offset, changes in ((reach, True), (-reach, True), (reach + 1, False), (-(reach + 1), False)):
        y = enc.apply(params, x.at[0, t + offset].add(5.0))[0, t]
        assert bool(jnp.any(jnp.abs(y - base) > 1e-6)) is changes, offset

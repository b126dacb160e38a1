"""ZeroEGGS networks (paper 001): sizes, KL and annealing, scan == loop, seeds, masking, training step."""

from __future__ import annotations

import json

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flax.training.train_state import TrainState

from jaxgest.runtime.errors import JaxgestError
from jaxgest.motion import rotations as R
from jaxgest.zeggs import features, losses, steps
from jaxgest.zeggs.api import count_params
from jaxgest.zeggs.config import LEGACY_DEFAULTS, Config, preset
from jaxgest.zeggs.generator import generate_loop_reference, update_character_state
from jaxgest.zeggs.model import ZeggsModel, init_params
from jaxgest.zeggs.style_encoder import StyleEncoder, sample_style
from zeggs_testing import zeggs_batch

TINY = preset("tiny")
CFG = TINY.model
P = CFG.pose_dim

_batch = zeggs_batch


@pytest.fixture(scope="module")
def params():
    return init_params(CFG, jax.random.key(0))


def test_config_json_round_trip():
    for name in ("tiny", "small", "paper"):
        cfg = preset(name)
        assert Config.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    assert preset("paper").model.pose_dim == 15 * 75 + 6
    with pytest.raises(JaxgestError, match=r"unknown ZeroEGGS preset 'huge' \(choose from paper, tiny, small\)"):
        preset("huge")
    with pytest.raises(ValueError, match="gru"):
        Config.from_dict({**preset("tiny").to_dict(), "model": {"gru": 3}})


def test_config_parts_hold_their_fields():
    """Model / train / inference fields are disjoint; overrides by bare name reach the right part."""
    c = preset("tiny").override(gru_hidden=16, learning_rate=3e-4, temperature=0.5)
    assert (c.model.gru_hidden, c.train.learning_rate, c.inference.temperature) == (16, 3e-4, 0.5)
    assert c.train == preset("tiny").train.replace(learning_rate=3e-4)
    parts = [set(Config().model.to_dict()), set(Config().train.to_dict()), set(Config().inference.to_dict())]
    assert not parts[0] & parts[1] and not parts[0] & parts[2]
    assert parts[1] & parts[2] == {"xla_opt_level"}  # the same XLA setting for training and inference


def test_flat_config_of_earlier_versions_maps_to_the_parts():
    """config.json of earlier versions held one flat dict: it is split by field, and a field those versions
    did not have yet (LEGACY_DEFAULTS) takes the old behaviour."""
    cfg = preset("small")
    flat = {**cfg.model.to_dict(), **cfg.train.to_dict(), **cfg.inference.to_dict(), "name": "small"}
    flat.pop("steps")  # the old flat config had no steps field
    flat = json.loads(json.dumps(flat))
    assert Config.from_dict(flat) == cfg.override(steps=Config().train.steps)
    old = {k: v for k, v in flat.items() if k not in LEGACY_DEFAULTS}
    restored = Config.from_dict(old)
    assert restored.model.loudness is False and restored.model.input_norm == "channel"
    assert restored.model.replace(**{k: getattr(cfg.model, k) for k in LEGACY_DEFAULTS}) == cfg.model
    with pytest.raises(ValueError, match="unknown"):
        Config.from_dict({**flat, "bogus": 1})


def _expected_counts(P, speech_in, channels, kernels, D_S, style_hidden, D_e, H, init_hidden, facing=3):
    """Parameter counts from the layer shapes of the authors' modules.py (PyTorch conventions), written out
    independently of the Flax modules: Conv1d ``i o k + o``, Linear ``i o + o``, LayerNorm ``2 d``,
    nn.MultiheadAttention ``3 (d d + d) + d d + d``, nn.GRU layer ``3 H (I + H) + 6 H``."""
    def linear(i, o):
        return i * o + o

    def conv(i, o, k):
        return i * o * k + o

    def gru(i, h):
        return 3 * h * (i + h) + 6 * h

    d = 2 * D_e  # the style encoder's second conv and FFT block width (mu and log-variance)
    speech = (conv(speech_in, channels[0], kernels[0]) + conv(channels[0], channels[1], kernels[1])
              + linear(channels[1], D_S))  # framewise linear (the code: conv1 outputs D_S, then D_S -> D_S)
    style = (conv(P, style_hidden, 3) + 2 * style_hidden + conv(style_hidden, d, 3) + 2 * d  # convs + LNs
             + 3 * (d * d + d) + linear(d, d) + 2 * d  # self-attention + LN
             + 2 * conv(d, d, 3) + 2 * d)  # position-wise conv feed-forward + LN
    x = P + facing + D_S + D_e  # [pose state, target facing, speech, style]
    generator = (linear(x, H) + gru(x + H, H) + gru(H, H) + linear(H, P)  # recurrent decoder, 2 GRU layers
                 + linear(P + facing + D_e, init_hidden) + linear(init_hidden, init_hidden)
                 + linear(init_hidden, 2 * H))  # hidden-state initializer
    return {"speech_encoder": speech, "style_encoder": style, "generator": generator}


def test_param_counts_paper_and_tiny():
    c = count_params("paper")
    # The paper's sizes (§4.2) on its 75-joint rig (P = 15 * 75 + 6), with the paper's k3 first speech conv
    # (the code has k1) and a 3-D target-facing input (the code feeds gaze targets instead).
    assert c == _expected_counts(1131, 81, (64, 64), (3, 31), 64, 512, 64, 1024, 1024)
    assert 25.0e6 < sum(c.values()) < 26.0e6  # "25M" (Table 2)
    t = preset("tiny").model
    assert count_params("tiny") == _expected_counts(t.pose_dim, 81, t.speech_channels, t.speech_kernels,
                                                    t.speech_embedding, t.style_hidden, t.style_embedding,
                                                    t.gru_hidden, t.init_hidden)
    shapes = jax.eval_shape(lambda k: init_params(CFG, k), jax.random.key(0))
    assert set(shapes) == {"speech_encoder", "style_encoder", "generator"}


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=4, max_size=4), st.lists(st.floats(-3, 3), min_size=4, max_size=4))
def test_kl_nonnegative(mu, logvar):
    mu, logvar = jnp.asarray([mu], jnp.float32), jnp.asarray([logvar], jnp.float32)
    for red in ("sum", "mean"):
        assert float(losses.kl_divergence(mu, logvar, reduction=red)[0]) >= -1e-6


def test_kl_zero_at_prior_and_positive_elsewhere():
    z = jnp.zeros((3, 8))
    np.testing.assert_allclose(losses.kl_divergence(z, z), 0.0, atol=1e-7)
    assert float(losses.kl_divergence(z + 0.5, z)[0]) == pytest.approx(8 * 0.125, rel=1e-5)


def test_kl_weight_monotone_and_capped():
    steps = np.arange(0, 30_000, 250)
    w = np.asarray(jax.vmap(lambda s: losses.kl_weight(s))(steps))
    assert np.all(np.diff(w) >= 0) and w.max() == pytest.approx(0.2) and w[0] < 1e-3
    assert float(losses.kl_weight(7500, cap=1.0)) == pytest.approx(0.5)


def test_character_state_matches_numpy_integration():
    rng = np.random.default_rng(1)
    T = 6
    vel = rng.normal(size=(T, 3)) * 30
    ang = np.zeros((T, 3))
    ang[:, 1] = rng.normal(size=T)  # yaw rate about Y
    pos_np, rot_np = features.integrate_root(vel, ang, CFG.fps)
    pose = np.zeros((T, P), np.float32)
    pose[:, CFG.layout.root_velocity] = vel
    pose[:, CFG.layout.root_angular_velocity] = ang
    p, q = jnp.zeros((1, 3)), jnp.asarray([[1.0, 0.0, 0.0, 0.0]])
    mean, std = jnp.zeros(P), jnp.ones(P)
    for t in range(1, T):
        p, q = update_character_state(jnp.asarray(pose[t:t + 1]), p, q, cfg=CFG, pose_mean=mean, pose_std=std)
        np.testing.assert_allclose(p[0], pos_np[t], atol=1e-3)
        np.testing.assert_allclose(R.quat_to_matrix(q[0]), R.quat_to_matrix(rot_np[t]), atol=1e-5)


def test_world_losses_zero_for_identical_and_facing_sensitive():
    rng = np.random.default_rng(2)
    pose = jnp.asarray(rng.normal(size=(2, 4, P)), jnp.float32)
    rp = jnp.asarray(rng.normal(size=(2, 4, 3)), jnp.float32)
    rr = R.quat_normalize(jnp.asarray(rng.normal(size=(2, 4, 4)), jnp.float32))
    terms = losses.reconstruction_terms(pose, rp, rr, pose, rp, rr, cfg=CFG)
    assert set(terms) == set(losses.term_weights(TINY.train))
    for k, v in terms.items():
        assert v.shape == (2,)
        np.testing.assert_allclose(v, 0.0, atol=1e-6, err_msg=k)
    turned = R.quat_mul(jnp.asarray([0.0, 0.0, 1.0, 0.0]), rr)  # 180 deg about Y
    t2 = losses.reconstruction_terms(pose, rp, rr, pose, rp, turned, cfg=CFG)
    assert float(t2["facing"].min()) > 0.1 and float(t2["local_position"].max()) == 0.0


# A 5-joint rig for the tiny preset: a static wrapper root, hips, spine, and two arms on the spine.
CHAIN_RIG = {"fk_parents": (-1, 0, 1, 2, 2), "fk_offsets": (0, 0, 0, 0, 90, 0, 0, 20, 0, 15, 5, 0, -15, 5, 0),
             "fk_translated": (0, 1)}


def test_fk_position_terms_follow_the_rendered_rotations():
    """With the rig in the config, position terms see the rotations (what is rendered), not the
    predicted position channels of joints below the hips, which only `predicted_position` sees."""
    cfg = CFG.replace(**CHAIN_RIG)
    rng = np.random.default_rng(3)
    j = cfg.num_joints
    lay = cfg.layout
    q = R.quat_normalize(rng.normal(size=(2, 4, j, 4)))
    pose = np.zeros((2, 4, P), np.float32)
    pose[..., lay.local_rotations] = R.quat_to_6d(q).reshape(2, 4, 6 * j)
    pose[..., lay.local_positions] = rng.normal(size=(2, 4, 3 * j))
    pose = jnp.asarray(pose)
    rp = jnp.zeros((2, 4, 3))
    rr = jnp.zeros((2, 4, 4)).at[..., 0].set(1.0)
    terms = losses.reconstruction_terms(pose, rp, rr, pose, rp, rr, cfg=cfg)
    for k, v in terms.items():
        np.testing.assert_allclose(v, 0.0, atol=1e-5, err_msg=k)
    # An arm's position channels moved: only predicted_position sees it.
    moved = pose.at[..., 3 * 3:3 * 4].add(10.0)
    t = losses.reconstruction_terms(moved, rp, rr, pose, rp, rr, cfg=cfg)
    assert float(t["predicted_position"].min()) > 1.0
    for k in ("local_position", "world_position", "fd_local_position", "fd_world_position"):
        np.testing.assert_allclose(t[k], 0.0, atol=1e-5, err_msg=k)
    # The spine turned: both arms move (local and world position terms), predicted_position does not.
    turned = np.asarray(pose).copy()
    q2 = q.copy()
    q2[..., 2, :] = R.quat_mul(R.euler_to_quat(np.array([0.0, 0.0, 40.0]), "XYZ"), q[..., 2, :])
    turned[..., lay.local_rotations] = R.quat_to_6d(q2).reshape(2, 4, 6 * j)
    t = losses.reconstruction_terms(jnp.asarray(turned), rp, rr, pose, rp, rr, cfg=cfg)
    assert float(t["local_position"].min()) > 0.5 and float(t["world_position"].min()) > 0.5
    np.testing.assert_allclose(t["predicted_position"], 0.0, atol=1e-6)
    # Without the rig (the old behaviour) the position terms read the channels and predicted_position is 0.
    t = losses.reconstruction_terms(moved, rp, rr, pose, rp, rr, cfg=CFG)
    assert float(t["local_position"].min()) > 1.0 and float(t["predicted_position"].max()) == 0.0


def _gen_inputs(B=2, T=5, seed=0):
    rng = np.random.default_rng(seed)
    q = np.zeros((B, 4), np.float32)
    q[:, 0] = 1.0
    return (jnp.asarray(rng.normal(size=(B, P)), jnp.float32), jnp.zeros((B, 3)), jnp.asarray(q),
            jnp.asarray(np.tile([0.6, 0.0, 0.8], (B, 1)), jnp.float32),
            jnp.asarray(rng.normal(size=(B, T, CFG.speech_embedding)), jnp.float32),
            jnp.asarray(rng.normal(size=(B, CFG.style_embedding)), jnp.float32))


def test_scan_generator_equals_python_loop(params):
    mean = jnp.asarray(np.linspace(-1, 1, P), jnp.float32)
    std = jnp.asarray(np.linspace(0.5, 2, P), jnp.float32)
    scan = jax.jit(lambda p, *a: ZeggsModel(CFG).apply({"params": p}, *a, mean, std,
                                                          method=ZeggsModel.generate),
                   compiler_options=TINY.train.compiler_options)
    pose0, rp0, rr0, facing, speech, style = _gen_inputs()
    out = scan(params, speech, style, pose0, rp0, rr0, facing)
    ref = generate_loop_reference(CFG, params["generator"], pose0, rp0, rr0, facing, speech, style, mean, std)
    for k in ("pose", "root_position", "root_rotation"):
        np.testing.assert_allclose(out[k], ref[k], rtol=1e-5, atol=1e-5)
    assert out["pose"].shape == (2, 5, P)
    np.testing.assert_array_equal(out["pose"][:, 0], pose0)  # frame 0 is the given pose
    assert float(jnp.abs(out["root_position"][:, -1]).max()) > 0  # the root moved by integration


def test_hoisted_weight_gradients_equal_the_plain_scan(params):
    """decoder_hoisted (weight gradients as one product over frames after the backward loop) gives the
    plain scan's outputs and the same gradients for every parameter and every input, up to summation order."""
    from jaxgest.zeggs.generator import Generator
    mean = jnp.asarray(np.linspace(-1, 1, P), jnp.float32)
    std = jnp.asarray(np.linspace(0.5, 2, P), jnp.float32)
    args = _gen_inputs(B=3, T=7, seed=1)
    w = jnp.asarray(np.random.default_rng(2).normal(size=(3, 7, P)), jnp.float32)

    def loss(p, speech, style, hoist):
        out = Generator(CFG, hoist_weight_grads=hoist).apply({"params": p}, *args[:4], speech, style, mean, std)
        return (jnp.sum(out["pose"] * w) + jnp.sum(jnp.sin(out["root_position"]))
                + jnp.sum(out["root_rotation"] ** 2)), out

    grads = {h: jax.jit(jax.grad(loss, argnums=(0, 1, 2), has_aux=True), static_argnums=3)(
        params["generator"], args[4], args[5], h) for h in (False, True)}
    (g_plain, out_plain), (g_hoist, out_hoist) = grads[False], grads[True]
    for k in out_plain:
        np.testing.assert_allclose(out_hoist[k], out_plain[k], rtol=1e-6, atol=1e-6)
    flat_p, flat_h = jax.tree_util.tree_leaves_with_path(g_plain), jax.tree_util.tree_leaves(g_hoist)
    assert jax.tree_util.tree_structure(g_plain) == jax.tree_util.tree_structure(g_hoist)
    for (path, a), b in zip(flat_p, flat_h):
        scale = float(jnp.abs(a).max()) + 1e-12
        np.testing.assert_allclose(np.asarray(b) / scale, np.asarray(a) / scale, atol=1e-5,
                                   err_msg=jax.tree_util.keystr(path))
    assert float(jnp.abs(g_hoist[0]["decoder"]["output_layer"]["kernel"]).max()) > 0  # gradients reach the weights


@pytest.fixture(scope="module")
def forward():
    b = _batch()

    @jax.jit
    def f(params, key, temperature):
        return ZeggsModel(CFG).apply(
            {"params": params}, b["speech"], b["style"], b["style_mask"], b["pose"][:, 0],
            b["root_position"][:, 0], b["root_rotation"][:, 0], b["facing"], key, temperature=temperature)
    return f


def test_same_seed_same_output_different_seed_differs(params, forward):
    a, aux_a = forward(params, jax.random.key(3), 1.0)
    b, _ = forward(params, jax.random.key(3), 1.0)
    c, aux_c = forward(params, jax.random.key(4), 1.0)
    np.testing.assert_array_equal(a["pose"], b["pose"])
    assert not np.allclose(a["pose"], c["pose"])
    np.testing.assert_array_equal(aux_a["mu"], aux_c["mu"])  # only the sample depends on the key
    _, aux_d = forward(params, jax.random.key(4), 0.0)  # temperature 0: the posterior mean
    np.testing.assert_allclose(aux_d["style_embedding"], aux_d["mu"], atol=1e-7)


def test_sample_style_temperature_scales_spread():
    mu, logvar = jnp.zeros((4000, 2)), jnp.zeros((4000, 2))
    e = sample_style(mu, logvar, jax.random.key(0), temperature=0.5)
    assert float(jnp.std(e)) == pytest.approx(0.5, rel=0.05)


def test_masked_style_batch_equals_one_at_a_time(params):
    b = _batch(B=2, S_=12)
    enc = StyleEncoder(CFG)
    apply = jax.jit(lambda p, x, m: enc.apply({"params": p}, x, m))
    mu, logvar = apply(params["style_encoder"], b["style"], b["style_mask"])
    for i, n in enumerate(b["style_mask"].sum(1)):
        x = b["style"][i:i + 1, :n]
        mu_i, lv_i = apply(params["style_encoder"], x, np.ones((1, n), bool))
        np.testing.assert_allclose(mu[i], mu_i[0], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(logvar[i], lv_i[0], rtol=1e-4, atol=1e-5)
    junk = b["style"].copy()  # the content of padded frames has no influence
    junk[1, 8:] = 1e3
    mu2, _ = apply(params["style_encoder"], junk, b["style_mask"])
    np.testing.assert_allclose(mu2, mu, rtol=1e-5, atol=1e-6)


def test_train_step_decreases_loss_without_retrace(params):
    """The step takes the pose statistics as an argument: other statistics of the same shape reuse the
    compilation (one trace)."""
    # Adam at 3e-3 instead of the paper's RAdam 1e-4 so 30 steps show learning; the step is the same.
    tx = optax.adam(3e-3)
    state = TrainState.create(apply_fn=ZeggsModel(CFG).apply, params=params, tx=tx)
    rng = np.random.default_rng(0)
    stats = steps.pose_stats(CFG, rng.normal(size=P), rng.uniform(0.5, 2.0, size=P))
    step = jax.jit(chex.assert_max_traces(steps.make_train_step(TINY), n=1),
                   donate_argnums=(0,), compiler_options=TINY.train.compiler_options)
    batch = _batch()
    key = jax.random.key(0)
    history = []
    for _ in range(30):
        state, m = step(state, batch, key, stats)
        history.append(float(m["loss"]))
    assert all(np.isfinite(history))
    assert np.mean(history[-3:]) < 0.8 * np.mean(history[:3]), history
    assert int(state.step) == 30
    assert {"loss", "recon", "kl", "kl_weight", "facing", "fd_world_position"} <= set(m)
    other = steps.pose_stats(CFG, rng.normal(size=P), rng.uniform(0.5, 2.0, size=P))
    state, m2 = step(state, batch, key, other)  # no retrace (assert_max_traces would raise)
    assert np.isfinite(float(m2["loss"])) and float(m2["loss"]) != history[-1]


def test_optimizer_is_radam_with_staircase_decay():
    """make_optimizer's own schedule: with a constant gradient RAdam's first (un-rectified) updates are
    -lr(t) exactly, so a decay every 2 steps by 0.5 shows as 1, 1, 0.5, 0.5 times the rate."""
    cfg = preset("paper").override(lr_decay_steps=2, lr_decay=0.5)
    tx = steps.make_optimizer(cfg)
    p = {"w": jnp.ones(3)}
    state = tx.init(p)
    g = {"w": jnp.ones(3)}
    seen = []
    for _ in range(4):
        upd, state = tx.update(g, state, p)
        seen.append(float(upd["w"][0]))
    np.testing.assert_allclose(seen, -1e-4 * np.array([1.0, 1.0, 0.5, 0.5]), rtol=1e-5)
    sched = steps.learning_rate_schedule(preset("paper"))  # the paper's: x0.995 every 1k steps
    assert float(sched(999)) == pytest.approx(1e-4) and float(sched(1000)) == pytest.approx(0.995e-4)


def test_compile_options_tiny_only_and_cli_overrides():
    from jaxgest.runtime.config import apply_overrides, parse_overrides
    from jaxgest.zeggs.trainer import DATA_FIELDS

    paper = preset("paper")
    assert paper.train.xla_opt_level is None and paper.train.compiler_options is None  # XLA defaults
    assert paper.inference.compiler_options is None
    assert TINY.train.compiler_options == TINY.inference.compiler_options == {"xla_backend_optimization_level": 0}
    old = {k: v for k, v in {**paper.model.to_dict(), **paper.train.to_dict()}.items()
           if k not in ("xla_opt_level", "steps")}  # a flat config.json from before the field
    assert Config.from_dict(old) == paper
    o = parse_overrides(["train.xla_opt_level=none", "model.gru_hidden=128", "model.speech_channels=32,32",
                         "train.mirror=false", "train.learning_rate=3e-4", "inference.temperature=0.5"])
    cfg = apply_overrides(TINY, o, model="ZeroEGGS", forbidden=DATA_FIELDS)
    assert cfg.train.xla_opt_level is None and cfg.inference.xla_opt_level == 0  # only the part named
    assert cfg.model.gru_hidden == 128 and cfg.model.speech_channels == (32, 32) and not cfg.train.mirror
    assert cfg.train.learning_rate == 3e-4 and cfg.inference.temperature == 0.5
    for bad, msg in (("gru=3", "unknown ZeroEGGS config field 'gru'"), ("model.num_joints=4", "set from the data"),
                     ("model.gru_hidden=big", "expected a int"), ("train.mirror=maybe", "expected a bool"),
                     ("gru_hidden=3", "closest: model.gru_hidden")):
        with pytest.raises(JaxgestError, match=msg):
            apply_overrides(TINY, parse_overrides([bad]), model="ZeroEGGS", forbidden=DATA_FIELDS)
    with pytest.raises(JaxgestError, match="expected KEY=VALUE"):
        parse_overrides(["model.gru_hidden"])


def test_to_world_equals_quaternion_rotation(key):
    k1, k2, k3 = jax.random.split(key, 3)
    parts = {n: jax.random.normal(k, (2, 5, 3, d)) for n, k, d in
             zip(("position", "rotation", "velocity", "angular"), jax.random.split(k1, 4), (3, 6, 3, 3))}
    q = R.quat_normalize(jax.random.normal(k2, (2, 5, 4)))
    r = jax.random.normal(k3, (2, 5, 3))
    w = losses.to_world(parts, r, q)
    qj = q[:, :, None]
    np.testing.assert_allclose(w["position"], R.quat_rotate(qj, parts["position"]) + r[:, :, None], atol=1e-5)
    rot = parts["rotation"]
    np.testing.assert_allclose(w["rotation"], jnp.concatenate(
        [R.quat_rotate(qj, rot[..., :3]), R.quat_rotate(qj, rot[..., 3:])], -1), atol=1e-5)
    for n in ("velocity", "angular"):
        np.testing.assert_allclose(w[n], R.quat_rotate(qj, parts[n]), atol=1e-5)


def test_input_normalisation_is_one_std_per_group_outputs_per_channel():
    """Inputs: (x - mean_c) / std of all the group's values (the authors' anim_input_std); outputs per channel.
    Near-constant channels are not blown up on the input side."""
    from jaxgest.zeggs.generator import input_scale

    rng = np.random.default_rng(4)
    x = rng.normal(size=(500, P)) * rng.uniform(0.01, 50.0, size=P) + rng.normal(size=P) * 10
    x[:, 3] = 7.0 + 1e-4 * rng.normal(size=500)  # a near-constant channel
    stats = features.pose_statistics([x[:250], x[250:]], trim=0)
    scale = np.asarray(input_scale(CFG, jnp.asarray(stats.mean), jnp.asarray(stats.std)))
    x_in = stats.normalize(x) * scale
    lay = CFG.layout
    for g in (lay.local_positions, lay.local_rotations, lay.local_velocities, lay.local_angular_velocities,
              lay.root_velocity, lay.root_angular_velocity):
        np.testing.assert_allclose(x_in[:, g], (x[:, g] - x[:, g].mean(0)) / x[:, g].std(), rtol=1e-6, atol=1e-9)
    assert np.abs(x_in[:, 3]).max() < 1e-3 and np.abs(stats.normalize(x)[:, 3]).max() > 2.0
    np.testing.assert_array_equal(input_scale(CFG.replace(input_norm="channel"), stats.mean, stats.std), 1.0)


def test_pose_statistics_leave_out_clip_ends():
    rng = np.random.default_rng(5)
    clips = [rng.normal(size=(40, 3)) for _ in range(3)]
    spiked = [c.copy() for c in clips]
    for c in spiked:
        c[:2] += 1e3  # boundary artefacts (copied velocities) at both ends
        c[-2:] -= 1e3
    a, b = features.pose_statistics(clips), features.pose_statistics(spiked)
    np.testing.assert_allclose(a.mean, b.mean)
    np.testing.assert_allclose(a.std, b.std)
    full = np.concatenate([c[2:-2] for c in clips])
    np.testing.assert_allclose(a.std, full.std(0))
    from jaxgest.motion.datasets import NormStats

    old = features.pose_statistics(spiked, input_norm="channel")  # the old statistics: every frame, floor 1e-2
    ref = NormStats.from_data(spiked)
    np.testing.assert_array_equal(old.mean, ref.mean)
    np.testing.assert_array_equal(old.std, ref.std)

"""TGST motion autoencoder: upsampling, reconstruction loss, training step, clip-end padding, frozen
standardisation statistics, and the autoencoder's training windows."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxgest.tgst import data as tdata
from jaxgest.tgst import model as tmodel
from jaxgest.tgst.autoencoder import expmap_reconstruction_loss, mean_angular_error_deg, upsample_linear
from jaxgest.tgst.model import init_params
from jaxgest.tgst.steps import create_ae_state, make_ae_train_step

from tgst_testing import CFG, FULL, TINY, normal, random_like, random_params, smooth_motion


@pytest.fixture(scope="module")
def params():
    return random_params()


def test_upsample_matches_pytorch_linear_align_corners_false():
    x = np.random.default_rng(0).normal(size=(1, 7, 3)).astype(np.float32)
    src = np.clip((np.arange(14) + 0.5) / 2 - 0.5, 0, None)
    i0 = np.floor(src).astype(int)
    i1 = np.minimum(i0 + 1, 6)
    lam = (src - i0)[None, :, None]
    expected = (1 - lam) * x[:, i0] + lam * x[:, i1]
    np.testing.assert_allclose(np.asarray(upsample_linear(jnp.asarray(x), 2)), expected, atol=1e-6)
    resized = jax.image.resize(jnp.asarray(x), (1, 14, 3), method="linear")
    np.testing.assert_allclose(np.asarray(resized), expected, atol=1e-6)


def test_reconstruction_loss_and_angle():
    target = normal(0, (2, 8, 6), 0.5)
    np.testing.assert_array_equal(np.asarray(expmap_reconstruction_loss(target, target)), 0.0)
    axis = np.array([0.0, 0.6, 0.8], np.float32)
    rot = jnp.asarray(np.tile(axis * 0.3, (2, 8, 2)))
    pred = rot + jnp.asarray(np.tile(axis * 0.1, (2, 8, 2)))  # same axis, 0.1 rad further
    np.testing.assert_allclose(np.asarray(expmap_reconstruction_loss(pred, rot)), 0.1, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(mean_angular_error_deg(pred, rot)), np.degrees(0.1), rtol=1e-3)
    full_turn = rot + jnp.asarray(np.tile(axis * 2 * np.pi, (2, 8, 2)))  # same rotation, other exp-map
    assert float(mean_angular_error_deg(full_turn, rot).max()) < 0.05


def test_ae_loss_decreases(params):
    tx = optax.adam(3e-3)
    state = create_ae_state(FULL, jax.tree_util.tree_map(jnp.copy, params["autoencoder"]), tx)  # donated
    step = jax.jit(make_ae_train_step(FULL, tx), donate_argnums=(0,))
    batch = {"upper": smooth_motion(10, 4, 64, 39), "lower": smooth_motion(11, 4, 64, 24)}
    key = jax.random.key(0)
    state, first = step(state, batch, key)
    for _ in range(29):
        state, metrics = step(state, batch, key)
    # the joint-displacement terms only when their weight is set (FULL: 0)
    assert set(metrics) == {"loss", "upper_loss", "lower_loss", "velocity_loss", "angle_deg"}
    assert float(metrics["loss"]) < 0.8 * float(first["loss"])
    assert float(metrics["angle_deg"]) < float(first["angle_deg"])
    assert int(state.step) == 30


def test_pad_clip_replicates_both_ends_and_trims_back():
    x = smooth_motion(11, 2, 37, 39)
    p = tmodel.pad_clip(x, cfg=CFG)
    lead, total = tmodel.edge_layout(37, cfg=CFG)
    assert lead == 16 and p.shape == (2, total, 39) and total % CFG.frame_multiple == 0
    assert total - 37 - lead >= lead  # the end gets at least as many copies
    np.testing.assert_array_equal(np.asarray(p[:, :lead]), np.broadcast_to(np.asarray(x[:, :1]), (2, lead, 39)))
    np.testing.assert_array_equal(np.asarray(p[:, lead + 37:]),
                                  np.broadcast_to(np.asarray(x[:, -1:]), (2, total - lead - 37, 39)))
    np.testing.assert_array_equal(np.asarray(tmodel.trim_clip(p, 37, cfg=CFG)), np.asarray(x))
    with pytest.raises(ValueError, match="edge_frames"):
        dataclasses.replace(CFG, edge_frames=4)  # tokens would not start at the clip's first frame


def test_constant_clip_reconstructs_constant_at_the_ends(params):
    """With edge padding the encoder's zero padding never reaches a real frame: a held pose decodes to the
    same pose on every frame, the first and last included (without it the first frames differ)."""
    pose = normal(12, (1, 1, 39), 0.5)
    x = jnp.broadcast_to(pose, (1, 48, 39))
    rec = jax.jit(tmodel.reconstruct, static_argnames="cfg")
    for cfg, constant in ((CFG, True), (dataclasses.replace(CFG, edge_frames=0), False)):
        up, lo = rec(params["autoencoder"], x, cfg=cfg)
        for y in (np.asarray(up[0]), np.asarray(lo[0])):
            spread = np.abs(y - y[20]).max()
            assert (spread < 1e-5) == constant, (cfg.edge_frames, spread)


def test_standardized_autoencoder_statistics_are_frozen():
    from jaxgest.tgst.losses import ae_loss_terms

    cfg = dataclasses.replace(CFG, autoencoder=dataclasses.replace(CFG.autoencoder, standardize=True))
    p = random_like(jax.eval_shape(lambda k: init_params(cfg, k), jax.random.key(0)))["autoencoder"]
    stats = {"upper_mean": jnp.full((39,), 0.3), "upper_std": jnp.full((39,), 2.0),
             "lower_mean": jnp.full((24,), -0.2), "lower_std": jnp.full((24,), 0.5)}
    p = dict(p, **stats)
    batch = {"upper": smooth_motion(17, 2, 32, 39), "lower": smooth_motion(18, 2, 32, 24)}
    grads = jax.jit(jax.grad(lambda q: jnp.mean(ae_loss_terms(q, batch, cfg=cfg)["loss"])))(p)
    tx = optax.adam(1e-2)
    updates, _ = tx.update(grads, tx.init(p), p)
    new = optax.apply_updates(p, updates)
    for k, v in stats.items():  # no gradient reaches the statistics, so Adam leaves them exactly unchanged
        np.testing.assert_array_equal(np.asarray(grads[k]), 0.0)
        np.testing.assert_array_equal(np.asarray(new[k]), np.asarray(v))
    assert np.abs(np.asarray(grads["encoder"]["conv_0"]["kernel"])).max() > 0
    # the statistics are used: the output is mean + std * (decoder output)
    rec = jax.jit(tmodel.reconstruct, static_argnames="cfg")
    up, _ = rec(p, batch["upper"], cfg=cfg)
    up0, _ = rec(dict(p, upper_mean=jnp.zeros(39)), batch["upper"], cfg=cfg)
    assert not np.allclose(np.asarray(up), np.asarray(up0))


def test_content_balanced_window_sampling():
    lengths = np.array([400] * 9 + [100])  # nine long clips of content "walk", one short "wave"
    groups = ["walk"] * 9 + ["wave"]
    rng = np.random.default_rng(0)
    idx = tdata.sample_windows_idx(lengths, 64, 4000, rng, [str(i) for i in range(10)], groups=groups)
    share = np.mean([i == 9 for i, _ in idx])
    assert 0.45 < share < 0.55  # uniform over windows would give 37 / (9 * 337 + 37) ~ 1 %
    assert all(0 <= s <= lengths[i] - 64 for i, s in idx)


def test_ae_batch_without_mirrored_clips():
    up = [np.full((80, 39), float(i), np.float32) for i in range(3)]
    lo = [np.zeros((80, 24), np.float32) for _ in range(3)]
    mup = [np.full((80, 39), -1.0 - i, np.float32) for i in range(3)]  # mirrored copies: negative values
    data = tdata.BodyData(up, lo, mup, lo, ["a", "b", "c"], 60.0, ["x", "x", "y"])
    for mirror in (True, False):
        ae = dataclasses.replace(TINY.train.autoencoder, mirror=mirror, batch_size=64, sampling="content")
        cfg = dataclasses.replace(TINY, train=dataclasses.replace(TINY.train, autoencoder=ae))
        b = tdata.ae_batch(data, cfg, 0, 0)["upper"]
        assert b.shape == (64, ae.window, 39)
        assert bool((b < 0).any()) == mirror


def _linear_path_cfg(standardize=True, latent_activation=True):
    ae = dataclasses.replace(CFG.autoencoder, linear_path=True, standardize=standardize,
                             latent_activation=latent_activation)
    return dataclasses.replace(CFG, autoencoder=ae)


@pytest.mark.parametrize("standardize", [True, False])
def test_linear_path_pca_init_reproduces_block_pca_exactly(standardize):
    """At step 0 the linear-path autoencoder (PCA-initialised, conv stacks' last layers zeroed) IS the block
    PCA of its training clips: the round trip equals baselines.block_pca_reconstruct, clip ends included."""
    from jaxgest.tgst import baselines
    from jaxgest.tgst.autoencoder import init_linear_path

    cfg = _linear_path_cfg(standardize)
    ups = [np.asarray(smooth_motion(20 + i, 1, 96, 39)[0]) for i in range(4)]
    los = [np.asarray(smooth_motion(30 + i, 1, 96, 24)[0]) for i in range(4)]
    p = random_like(jax.eval_shape(lambda k: init_params(cfg, k), jax.random.key(0)))["autoencoder"]
    if standardize:
        stats = tdata.channel_stats(tdata.BodyData(ups, los, ups, los, list("abcd"), 60.0))
        p = dict(p, **{k: jnp.asarray(v) for k, v in stats.items()})
    p = init_linear_path(p, cfg.autoencoder, ups, los)
    pca = baselines.block_pca_fit(ups, components=cfg.autoencoder.latent_dim, frames=4)
    x = ups[1][:70]  # not a multiple of 4 frames: the end block is replicated like the baseline's
    up, lo = jax.jit(tmodel.reconstruct, static_argnames="cfg")(p, jnp.asarray(x)[None], cfg=cfg)
    ref = baselines.block_pca_reconstruct(pca, x)
    np.testing.assert_allclose(np.asarray(up[0]), ref, atol=2e-5)
    assert np.abs(ref - x).max() > 1e-3  # a real (lossy) reconstruction, not the identity
    # the lower body is the least-squares map of the same codes: better than its mean on the training clips
    lo_all = np.concatenate(los)
    lo_hat = np.asarray(jax.jit(tmodel.reconstruct, static_argnames="cfg")(
        p, jnp.asarray(np.stack(ups)), cfg=cfg)[1]).reshape(-1, 24)
    assert np.mean((lo_hat - lo_all) ** 2) < np.mean((lo_all - lo_all.mean(0)) ** 2)


def test_linear_path_and_latent_activation_change_the_model_as_stated():
    from jaxgest.tgst.autoencoder import MotionAutoencoder

    base = jax.eval_shape(lambda k: init_params(CFG, k), jax.random.key(0))["autoencoder"]
    lin = jax.eval_shape(lambda k: init_params(_linear_path_cfg(False), k), jax.random.key(0))["autoencoder"]
    assert set(lin) - set(base) == {"linear_encoder", "linear_upper", "linear_lower"}
    assert lin["linear_encoder"]["kernel"].shape == (4, 39, 16)
    assert lin["linear_upper"]["kernel"].shape == (16, 4 * 39)
    assert lin["linear_lower"]["kernel"].shape == (16, 4 * 24)
    # without the latent GELU the latent takes values below GELU's minimum (-0.17)
    x = smooth_motion(40, 2, 64, 39) * 3.0
    for act, can_go_low in ((True, False), (False, True)):
        cfg = dataclasses.replace(CFG, autoencoder=dataclasses.replace(CFG.autoencoder, latent_activation=act))
        p = random_params()["autoencoder"]
        z = MotionAutoencoder(cfg.autoencoder).apply({"params": p}, x, method=MotionAutoencoder.encode)
        assert bool((np.asarray(z) < -0.2).any()) == can_go_low


# ----- the joint-displacement recipe term (train.autoencoder.position_velocity_weight) ----------------------

def _body_motion(upper, lower):
    """The canonical body posed by body exp-maps through the Motion/numpy FK path, joints looked up by name,
    Hips at the origin: an independent route to :func:`autoencoder.body_positions`."""
    from jaxgest.motion import body
    from jaxgest.motion import kinematics as K
    from jaxgest.motion import rotations as R
    from jaxgest.motion.skeleton import Motion

    sk = body.body_skeleton()
    f = upper.shape[0]
    ex = {n: v for n, v in zip(body.UPPER, upper.reshape(f, -1, 3).transpose(1, 0, 2))}
    ex.update({n: v for n, v in zip(body.LOWER, lower.reshape(f, -1, 3).transpose(1, 0, 2))})
    rots = np.stack([R.expmap_to_quat(ex[n].astype(np.float64)) for n in sk.names], axis=1)
    trans = np.broadcast_to(sk.offsets, (f,) + sk.offsets.shape).copy()
    trans[:, sk.names.index("Hips")] = 0.0
    return K.forward_kinematics(Motion(sk, rots, trans, fps=30.0))


def test_body_positions_are_forward_kinematics_of_the_body_with_the_hips_at_the_origin():
    from jaxgest.tgst.autoencoder import body_positions

    rng = np.random.default_rng(3)
    upper, lower = rng.normal(0, 0.6, (5, 39)), rng.normal(0, 0.6, (5, 24))
    got = np.asarray(body_positions(jnp.asarray(upper, jnp.float32), jnp.asarray(lower, jnp.float32)))
    np.testing.assert_allclose(got, _body_motion(upper, lower), atol=1e-3)  # cm, float32
    from jaxgest.motion import body

    sk = body.body_skeleton()
    par = np.asarray(sk.parents)
    assert np.abs(got[:, par < 0]).max() == 0  # the Hips at the origin
    bones = np.linalg.norm(got[:, par >= 0] - got[:, par[par >= 0]], axis=-1)
    np.testing.assert_allclose(bones, np.broadcast_to(np.linalg.norm(sk.offsets[par >= 0], axis=-1), bones.shape),
                               rtol=1e-4)  # bone lengths of the body


def test_position_velocity_loss_zeros_and_lever_arms():
    from jaxgest.motion import body
    from jaxgest.tgst.autoencoder import expmap_velocity_loss, position_velocity_errors, position_velocity_loss

    def pvl(pu, pl, u, l, joints="all"):
        return position_velocity_loss(position_velocity_errors(pu, pl, u, l), joints)

    rng = np.random.default_rng(4)
    upper = jnp.asarray(np.cumsum(rng.normal(0, 0.05, (2, 12, 39)), axis=1) + rng.normal(0, 0.4, (2, 1, 39)),
                        jnp.float32)
    lower = jnp.asarray(rng.normal(0, 0.4, (2, 12, 24)), jnp.float32)
    assert np.all(np.asarray(pvl(upper, lower, upper, lower)) == 0)
    # a joint without child joints (hands, head, toes): its rotation moves no joint position
    hand = 3 * body.UPPER.index("Hand_L")
    moved = upper.at[..., hand:hand + 3].add(jnp.asarray(rng.normal(0, 0.5, (2, 12, 3)), jnp.float32))
    np.testing.assert_allclose(np.asarray(pvl(moved, lower, upper, lower)), 0, atol=1e-4)
    assert np.all(np.asarray(expmap_velocity_loss(moved, upper)) > 0.02)  # the exp-map term does see it
    # the same jitter on the spine costs more than on a forearm (longer lever arm: everything above it)
    jitter = jnp.asarray(rng.normal(0, 0.02, (2, 12, 3)), jnp.float32)
    costs = {}
    for joint in ("Spine", "LowerArm_L"):
        j = 3 * body.UPPER.index(joint)
        costs[joint] = np.asarray(pvl(upper.at[..., j:j + 3].add(jitter), lower, upper, lower))
    assert np.all(costs["Spine"] > 2 * costs["LowerArm_L"])
    # "upper": the legs' displacements left out (a leg change costs nothing there, something with "all")
    knee = 3 * body.LOWER.index("UpperLeg_L")
    legs = lower.at[..., knee:knee + 3].add(jnp.asarray(rng.normal(0, 0.3, (2, 12, 3)), jnp.float32))
    assert np.all(np.asarray(pvl(upper, legs, upper, lower, "upper")) == 0)
    assert np.all(np.asarray(pvl(upper, legs, upper, lower, "all")) > 0.1)
    # the upper mean is the mean over the 13 upper joints: 21/13 x the all-joint mean of an upper-only change
    spine = upper.at[..., 3:6].add(jitter)
    np.testing.assert_allclose(np.asarray(pvl(spine, lower, upper, lower, "upper")),
                               21 / 13 * np.asarray(pvl(spine, lower, upper, lower, "all")), rtol=1e-5)
    with pytest.raises(ValueError, match="joints must be one of"):
        pvl(upper, lower, upper, lower, "arms")


@pytest.mark.parametrize("weights", [(0.0, 0.0, "all", 1.0), (0.0, 0.5, "all", 1.0), (3.0, 0.5, "upper", 1.0),
                                     (2.0, 0.0, "all", 4.0)])
def test_ae_step_minimises_the_stated_objective(params, weights):
    """One plain gradient step (SGD, lr 1) moves the parameters by minus the gradient of loss +
    velocity_weight x velocity_loss + position_velocity_weight x the position term of the chosen joints, with
    the trunk joints' exp-map errors counted trunk_weight times in the first two (written out per joint here)."""
    from jaxgest.tgst import model as M
    from jaxgest.tgst.losses import ae_loss_terms

    vw, pw, joints, tw = weights
    ae_train = dataclasses.replace(FULL.train.autoencoder, velocity_weight=vw, position_velocity_weight=pw,
                                   position_velocity_joints=joints, trunk_weight=tw)
    cfg = dataclasses.replace(FULL, train=dataclasses.replace(FULL.train, autoencoder=ae_train))
    p0 = params["autoencoder"]
    batch = {"upper": smooth_motion(12, 2, 32, 39), "lower": smooth_motion(13, 2, 32, 24)}
    w = np.ones(21, np.float32)
    w[:3] = tw  # Hips, Spine, Chest: the first three upper-body joints

    def per_joint(pred, target):  # mean over batch and frames of ||r_hat - r|| per joint, (21,)
        d = (pred - target).reshape(pred.shape[:2] + (21, 3))
        return jnp.mean(jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-12), axis=(0, 1))

    def objective(p):
        t = {k: jnp.mean(v) for k, v in ae_loss_terms(p, batch, cfg=cfg.model).items()}
        pos = t["position_velocity_loss"] if joints == "all" else t["upper_position_velocity_loss"]
        pred = jnp.concatenate(M.reconstruct(p, batch["upper"], cfg=cfg.model), axis=-1)
        target = jnp.concatenate([batch["upper"], batch["lower"]], axis=-1)
        rec = jnp.sum(w * per_joint(pred, target)) / 21
        vel = jnp.sum(w * per_joint(jnp.diff(pred, axis=1), jnp.diff(target, axis=1))) / 21
        return rec + vw * vel + pw * pos

    expected = jax.tree_util.tree_map(lambda a, g: a - g, p0, jax.grad(objective)(p0))
    tx = optax.sgd(1.0)
    state = create_ae_state(cfg, jax.tree_util.tree_map(jnp.copy, p0), tx)
    state, metrics = jax.jit(make_ae_train_step(cfg, tx))(state, batch, jax.random.key(0))
    assert ("position_velocity_loss" in metrics) == (pw > 0)  # computed (and logged) only when weighted
    assert ("trunk_loss" in metrics) == (tw != 1.0)
    for a, b in zip(jax.tree_util.tree_leaves(state.params), jax.tree_util.tree_leaves(expected)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-6)

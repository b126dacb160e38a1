"""TGST (paper 000) models: parameter counts, attention band, transfer API, training steps."""

from __future__ import annotations

import dataclasses
import json

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.tgst import api
from jaxgest.tgst import data as tdata
from jaxgest.tgst import model as tmodel
from jaxgest.tgst.autoencoder import (MotionAutoencoder, expmap_reconstruction_loss, mean_angular_error_deg,
                                      upsample_linear)
from jaxgest.tgst.config import Config, ModelConfig, preset
from jaxgest.tgst.model import init_params, transfer_arrays
from jaxgest.tgst.steps import (create_ae_state, create_transformer_state, make_ae_train_step,
                                make_transformer_train_step)
from jaxgest.tgst.tokens import ClipTooShortError
from jaxgest.tgst.transformer import (StyleTransformer, StyleTransformerEncoder, band_mask,
                                      blockwise_banded_attention, dense_banded_attention)

TINY = preset("tiny")
# omega = 2 so that the band matters on short test clips (7 tokens for 64 frames)
CFG = dataclasses.replace(TINY.model, transformer=dataclasses.replace(TINY.model.transformer, omega=2, block_size=4))
FULL = dataclasses.replace(TINY, model=CFG)  # the preset with that model, for the training steps


def _normal(seed, shape, scale=1.0):
    return jnp.asarray(scale * np.random.default_rng(seed).normal(size=shape), jnp.float32)


def _smooth_motion(seed, batch, frames, channels):
    """Smooth sinusoidal exp-maps (learnable by the conv autoencoder)."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[None, :, None] / 60.0
    freq, phase, amp = (rng.uniform(0.3, 2.0, (batch, 1, channels)), rng.uniform(0, 6, (batch, 1, channels)),
                        rng.uniform(0.1, 0.6, (batch, 1, channels)))
    return jnp.asarray(amp * np.sin(2 * np.pi * freq * t + phase), jnp.float32)


def _random_like(shapes, seed=0):
    """Random parameters with the structure of ``shapes`` (kernels ~ N(0, 1/fan_in), LN scales 1, biases 0).

    Filled with NumPy: compiling Flax's initialisers costs seconds per model on this machine, and the
    initialisers themselves are not under test here (their structure is, via ``jax.eval_shape``).
    """
    rng = np.random.default_rng(seed)

    def fill(path, leaf):
        name = jax.tree_util.keystr(path)
        if "scale" in name:
            return jnp.ones(leaf.shape, leaf.dtype)
        if "bias" in name:
            return jnp.zeros(leaf.shape, leaf.dtype)
        fan_in = int(np.prod(leaf.shape[:-1])) if len(leaf.shape) > 1 else 1
        return jnp.asarray(rng.normal(size=leaf.shape) / np.sqrt(fan_in), leaf.dtype)

    return jax.tree_util.tree_map_with_path(fill, shapes)


@pytest.fixture(scope="module")
def params():
    return _random_like(jax.eval_shape(lambda k: init_params(CFG, k), jax.random.key(0)))


def _count(tree):
    return int(sum(x.size for x in jax.tree_util.tree_leaves(tree)))


# ---------------------------------------------------------------- sizes and configs

def test_param_counts_paper():
    assert api.count_params("paper") == {"autoencoder": 23743, "transformer": 50240}


@pytest.mark.parametrize("variant", ["paper", "authors"])
@pytest.mark.parametrize("lns,expected", [(1, 50240), (2, 50496)])
def test_transformer_param_count_layernorms(variant, lns, expected):
    tcfg = dataclasses.replace(preset("paper").model.transformer, layernorms_per_block=lns, variant=variant)
    tok = jnp.zeros((1, 5, 64))
    shapes = jax.eval_shape(StyleTransformer(tcfg).init, jax.random.key(0), tok, tok)
    assert _count(shapes) == expected


def test_autoencoder_layer_sizes_and_shapes():
    ae = MotionAutoencoder(preset("paper").model.autoencoder)
    shapes = jax.eval_shape(ae.init, jax.random.key(0), jnp.zeros((2, 64, 39)))["params"]
    sizes = {part: [_count(shapes[part][f"conv_{i}"]) for i in range(3)]
             for part in ("encoder", "upper_decoder", "lower_decoder")}
    assert sizes == {"encoder": [2560, 6176, 1552], "upper_decoder": [1568, 6208, 2535],
                     "lower_decoder": [784, 1568, 792]}
    variables = {"params": shapes}
    z = jax.eval_shape(lambda v, x: ae.apply(v, x, method=MotionAutoencoder.encode), variables,
                       jnp.zeros((2, 64, 39)))
    assert z.shape == (2, 16, 16)
    (up, lo), _ = jax.eval_shape(ae.apply, variables, jnp.zeros((2, 64, 39)))
    assert up.shape == (2, 64, 39) and lo.shape == (2, 64, 24)


def test_config_json_round_trip_and_validation():
    from jaxgest.tgst.config import PRESETS
    from jaxgest.tgst.train import DEFAULT_STEPS

    assert set(PRESETS) == set(DEFAULT_STEPS)
    for name in PRESETS:
        cfg = preset(name)
        assert Config.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
        hash(cfg), hash(cfg.model)  # usable as jit static arguments
    with pytest.raises(ValueError):
        preset("huge")
    with pytest.raises(ValueError, match="block_size"):
        ModelConfig(transformer=dataclasses.replace(TINY.model.transformer, block_size=8))


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
    target = _normal(0, (2, 8, 6), 0.5)
    np.testing.assert_array_equal(np.asarray(expmap_reconstruction_loss(target, target)), 0.0)
    axis = np.array([0.0, 0.6, 0.8], np.float32)
    rot = jnp.asarray(np.tile(axis * 0.3, (2, 8, 2)))
    pred = rot + jnp.asarray(np.tile(axis * 0.1, (2, 8, 2)))  # same axis, 0.1 rad further
    np.testing.assert_allclose(np.asarray(expmap_reconstruction_loss(pred, rot)), 0.1, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(mean_angular_error_deg(pred, rot)), np.degrees(0.1), rtol=1e-3)
    full_turn = rot + jnp.asarray(np.tile(axis * 2 * np.pi, (2, 8, 2)))  # same rotation, other exp-map
    assert float(mean_angular_error_deg(full_turn, rot).max()) < 0.05


# ---------------------------------------------------------------- attention band

@pytest.mark.parametrize("variant", ["paper", "authors"])
@pytest.mark.parametrize("n", [1, 9, 23])
def test_blockwise_equals_dense(variant, n):
    q, k, v = (_normal(s, (2, n + 1, 8)) for s in (1, 2, 3))

    @jax.jit
    def both(q, k, v):
        dense, _ = dense_banded_attention(q, k, v, omega=3, variant=variant)
        return dense, blockwise_banded_attention(q, k, v, omega=3, variant=variant, block_size=4)

    dense, block = both(q, k, v)
    np.testing.assert_allclose(np.asarray(block), np.asarray(dense), atol=1e-5)


def test_band_masks():
    m = band_mask(8, omega=2, variant="paper")
    assert m[0].all() and m[:, 0].all()
    assert m[5, 3] and m[5, 7] and not m[5, 2] and not m[5, 8]
    a = band_mask(8, omega=2, variant="authors")
    assert a[0].all() and a[2, 0] and not a[3, 0]  # CLS visible to gesture rows i <= omega only
    assert a[5, 3] and a[5, 6] and not a[5, 7] and not a[5, 2]  # i - omega <= j < i + omega


@pytest.fixture(scope="module")
def encoders():
    """Jitted encoders (blockwise, dense) sharing one set of parameters; omega = 3, 24 tokens."""
    out = {}
    tok = _normal(0, (1, 24, 64))
    variables = None
    for impl in ("blockwise", "dense"):
        tcfg = dataclasses.replace(TINY.model.transformer, omega=3, block_size=4, attention_impl=impl)
        enc = StyleTransformerEncoder(tcfg)
        variables = variables or _random_like(jax.eval_shape(enc.init, jax.random.key(1), tok), seed=1)
        out[impl] = jax.jit(lambda t, enc=enc: enc.apply(variables, t))
    return out, tok


def test_encoder_blockwise_equals_dense(encoders):
    fns, tok = encoders
    (yb, auxb), (yd, auxd) = fns["blockwise"](tok), fns["dense"](tok)
    np.testing.assert_allclose(np.asarray(yb), np.asarray(yd), atol=1e-5)
    np.testing.assert_allclose(np.asarray(auxb["keys"]), np.asarray(auxd["keys"]), atol=1e-6)
    assert auxd["attention"].shape == (1, 25, 25) and "attention" not in auxb


@settings(max_examples=15, deadline=None)
@given(i=st.integers(0, 23), j=st.integers(0, 23), impl=st.sampled_from(["blockwise", "dense"]))
def test_tokens_beyond_omega_have_no_influence(encoders, i, j, impl):
    fns, tok = encoders
    y0, aux0 = fns[impl](tok)
    y1, aux1 = fns[impl](tok.at[0, j].add(_normal(99, (64,))))  # not constant: LayerNorm would remove it
    changed = not np.allclose(np.asarray(y0[0, 1 + i]), np.asarray(y1[0, 1 + i]), atol=1e-5)
    assert changed == (abs(i - j) <= 3)
    assert not np.allclose(np.asarray(aux0["cls"]), np.asarray(aux1["cls"]))  # CLS attends to all


# ---------------------------------------------------------------- transfer API

def test_all_methods_run_with_right_shapes(params):
    content, style = _smooth_motion(1, 2, 50, 39), _smooth_motion(2, 2, 70, 39)
    methods = tmodel.METHODS

    @jax.jit  # one compilation for the five methods
    def run_all(params, content, style):
        return {m: transfer_arrays(params, content, style, cfg=CFG, method=m) for m in methods}

    results = run_all(params, content, style)
    for method, (up, lo, aux) in results.items():
        assert up.shape == (2, 50, 39) and lo.shape == (2, 50, 24), method
        assert bool(jnp.isfinite(up).all() & jnp.isfinite(lo).all()), method
        # 50 frames + 16 edge frames at both ends -> padded 96 -> 24 latent frames
        assert aux["content_latents"].shape == (2, 24, 16)
    recon = jax.jit(tmodel.reconstruct, static_argnames="cfg")(params["autoencoder"], content, cfg=CFG)
    np.testing.assert_allclose(np.asarray(results["autoencoder"][0]), np.asarray(recon[0]), atol=1e-6)
    np.testing.assert_allclose(np.asarray(results["autoencoder"][1]), np.asarray(recon[1]), atol=1e-6)
    assert not np.allclose(np.asarray(results["soft"][0]), np.asarray(results["adain"][0]))
    with pytest.raises(ValueError, match="unknown transfer method"):
        transfer_arrays(params, content, style, cfg=CFG, method="magic")


@pytest.fixture(scope="module")
def traced_soft():
    @jax.jit
    @chex.assert_max_traces(n=1)
    def fn(params, content, style):
        return transfer_arrays(params, content, style, cfg=CFG, method="soft")

    return fn


def test_jit_equals_eager_and_no_retrace(params, traced_soft):
    content, style = _smooth_motion(3, 1, 40, 39), _smooth_motion(4, 1, 33, 39)
    up_j, lo_j, aux_j = traced_soft(params, content, style)
    up_e, lo_e, _ = transfer_arrays(params, content, style, cfg=CFG, method="soft")  # op by op
    np.testing.assert_allclose(np.asarray(up_j), np.asarray(up_e), atol=1e-5)
    np.testing.assert_allclose(np.asarray(lo_j), np.asarray(lo_e), atol=1e-5)
    w = aux_j["swap_weights"]  # soft swap weights: rows on the simplex over the style tokens
    np.testing.assert_allclose(np.asarray(w.sum(-1)), 1.0, rtol=1e-5)
    traced_soft(params, content + 0.1, style - 0.1)  # same shapes: must not retrace
    with pytest.raises(AssertionError):
        traced_soft(params, _smooth_motion(5, 1, 48, 39), style)  # new shape retraces (the guard works)


def test_short_clip_error(params):
    with pytest.raises(ClipTooShortError, match="15 frames"):
        transfer_arrays(params, jnp.zeros((1, 15, 39)), jnp.zeros((1, 32, 39)), cfg=CFG)
    with pytest.raises(ClipTooShortError):
        transfer_arrays(params, jnp.zeros((1, 32, 39)), jnp.zeros((1, 8, 39)), cfg=CFG)


def test_authors_variant_runs(params):
    acfg = dataclasses.replace(CFG, transformer=dataclasses.replace(CFG.transformer, variant="authors"))
    content = jnp.concatenate([_smooth_motion(6, 1, 32, 39)] * 2)  # the same clip twice
    up, lo, _ = jax.jit(transfer_arrays, static_argnames=("cfg", "method"))(
        params, content, _smooth_motion(7, 2, 40, 39), cfg=acfg)
    assert up.shape == (2, 32, 39) and bool(jnp.isfinite(up).all())


# ---------------------------------------------------------------- training steps

def test_ae_loss_decreases(params):
    tx = optax.adam(3e-3)
    state = create_ae_state(FULL, jax.tree_util.tree_map(jnp.copy, params["autoencoder"]), tx)  # donated
    step = jax.jit(make_ae_train_step(FULL, tx), donate_argnums=(0,))
    batch = {"upper": _smooth_motion(10, 4, 64, 39), "lower": _smooth_motion(11, 4, 64, 24)}
    key = jax.random.key(0)
    state, first = step(state, batch, key)
    for _ in range(29):
        state, metrics = step(state, batch, key)
    assert set(metrics) == {"loss", "upper_loss", "lower_loss", "angle_deg"}
    assert float(metrics["loss"]) < 0.8 * float(first["loss"])
    assert float(metrics["angle_deg"]) < float(first["angle_deg"])
    assert int(state.step) == 30


def test_transformer_loss_decreases(params):
    tx = optax.adam(1e-3)
    state = create_transformer_state(FULL, jax.tree_util.tree_map(jnp.copy, params["transformer"]), tx)
    step = jax.jit(make_transformer_train_step(FULL, tx, params["autoencoder"]), donate_argnums=(0,))
    batch = {"content": _smooth_motion(12, 2, 64, 39), "style": _smooth_motion(13, 2, 48, 39)}
    key = jax.random.key(0)
    state, first = step(state, batch, key)
    for _ in range(29):
        state, metrics = step(state, batch, key)
    assert set(metrics) == {"loss", "identity", "cyclic", "structure", "appearance"}
    assert all(bool(jnp.isfinite(v)) for v in metrics.values())
    assert float(metrics["loss"]) < 0.8 * float(first["loss"])


# ---------------------------------------------------------------- clip ends, swap weights, recipe options

def test_pad_clip_replicates_both_ends_and_trims_back():
    x = _smooth_motion(11, 2, 37, 39)
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
    pose = _normal(12, (1, 1, 39), 0.5)
    x = jnp.broadcast_to(pose, (1, 48, 39))
    rec = jax.jit(tmodel.reconstruct, static_argnames="cfg")
    for cfg, constant in ((CFG, True), (dataclasses.replace(CFG, edge_frames=0), False)):
        up, lo = rec(params["autoencoder"], x, cfg=cfg)
        for y in (np.asarray(up[0]), np.asarray(lo[0])):
            spread = np.abs(y - y[20]).max()
            assert (spread < 1e-5) == constant, (cfg.edge_frames, spread)


def test_swap_weights_rows_on_simplex_and_match_transfer(params):
    content, style = _smooth_motion(13, 2, 50, 39), _smooth_motion(14, 2, 70, 39)
    fn = jax.jit(tmodel.swap_weights, static_argnames="cfg")
    w = np.asarray(fn(params, content, style, cfg=CFG))
    n_c = tmodel.num_tokens(-(-50 // 4))  # tokens of the real content frames only
    n_s = tmodel.num_tokens(-(-70 // 4))
    assert w.shape == (2, n_c, n_s)
    np.testing.assert_allclose(w.sum(-1), 1.0, rtol=1e-5)
    _, _, aux = jax.jit(transfer_arrays, static_argnames=("cfg", "method"))(params, content, style, cfg=CFG)
    np.testing.assert_allclose(np.asarray(aux["swap_weights"])[:, 2:2 + n_c], w, atol=1e-6)


@pytest.mark.parametrize("similarity,positions", [("dot", "none"), ("scaled", "index"), ("scaled", "none")])
def test_swap_options_run_and_keep_the_simplex(params, similarity, positions):
    cfg = dataclasses.replace(CFG, swap_similarity=similarity,
                              transformer=dataclasses.replace(CFG.transformer, token_positions=positions))
    content, style = _smooth_motion(15, 1, 40, 39), _smooth_motion(16, 1, 40, 39)
    w = np.asarray(jax.jit(tmodel.swap_weights, static_argnames="cfg")(params, content, style, cfg=cfg))
    np.testing.assert_allclose(w.sum(-1), 1.0, rtol=1e-5)
    if similarity == "scaled":  # bounded logits: no row can be one-hot from untrained random tokens
        assert w.max() < 0.99
    with pytest.raises(ValueError, match="swap_similarity"):
        dataclasses.replace(CFG, swap_similarity="cosine")


def test_standardized_autoencoder_statistics_are_frozen():
    from jaxgest.tgst.losses import ae_loss_terms

    cfg = dataclasses.replace(CFG, autoencoder=dataclasses.replace(CFG.autoencoder, standardize=True))
    p = init_params(cfg, jax.random.key(0))["autoencoder"]
    stats = {"upper_mean": jnp.full((39,), 0.3), "upper_std": jnp.full((39,), 2.0),
             "lower_mean": jnp.full((24,), -0.2), "lower_std": jnp.full((24,), 0.5)}
    p = dict(p, **stats)
    batch = {"upper": _smooth_motion(17, 2, 32, 39), "lower": _smooth_motion(18, 2, 32, 24)}
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


def test_flat_config_of_older_versions_maps_to_the_split_with_old_defaults():
    from jaxgest.tgst.config import legacy_to_dict

    new = preset("paper")
    old = {"name": "paper", **new.model.to_dict(), "ae_window": 192, "use_cyclic": False, "ae_mirror": False}
    for k in ("edge_frames", "swap_similarity"):  # fields added later: absent in the oldest workdirs
        old.pop(k)
    old["transformer"].pop("token_positions")
    old["autoencoder"].pop("standardize")
    cfg = Config.from_dict(json.loads(json.dumps(old)))
    m = cfg.model
    assert m.edge_frames == 0 and m.swap_similarity == "dot" and m.transformer.token_positions == "index"
    assert cfg.train.autoencoder.window == 192 and not cfg.train.autoencoder.mirror
    assert not cfg.train.transformer.use_cyclic and cfg.train.transformer.use_identity
    assert legacy_to_dict(old)["model"]["fps"] == new.model.fps


def test_content_balanced_window_sampling():
    lengths = np.array([400] * 9 + [100])  # nine long clips of content "walk", one short "wave"
    groups = ["walk"] * 9 + ["wave"]
    rng = np.random.default_rng(0)
    idx = tdata.sample_windows_idx(lengths, 64, 4000, rng, [str(i) for i in range(10)], groups=groups)
    share = np.mean([i == 9 for i, _ in idx])
    assert 0.45 < share < 0.55  # uniform over windows would give 37 / (9 * 337 + 37) ~ 1 %
    assert all(0 <= s <= lengths[i] - 64 for i, s in idx)


def test_apply_overrides_reaches_sub_configs_and_rejects_bad_values():
    from jaxgest.errors import JaxgestError
    from jaxgest.tgst.train import apply_overrides

    cfg = apply_overrides(preset("fit"), {"swap_similarity": "scaled", "transformer.token_positions": "index",
                                          "model.autoencoder.standardize": False, "train.autoencoder.window": 32,
                                          "ae_batch_size": 2})
    m = cfg.model
    assert m.swap_similarity == "scaled" and m.transformer.token_positions == "index"
    assert not m.autoencoder.standardize and m.edge_frames == 16
    assert cfg.train.autoencoder.window == 32 and cfg.train.autoencoder.batch_size == 2
    assert apply_overrides(TINY, None) == TINY
    with pytest.raises(JaxgestError, match="override"):
        apply_overrides(TINY, {"swap_similarity": "cosine"})


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


def test_checkpoints_check_only_the_model_config(tmp_path):
    """The autoencoder checkpoint checks the autoencoder's part of the model config: other training settings or
    transformer sizes share it, another autoencoder setting is a mismatch naming the field. A checkpoint of the
    flat layout of older versions (whole config, fields it predates absent) matches the same model."""
    import types

    from jaxgest import training
    from jaxgest.errors import CheckpointError
    from jaxgest.tgst.workdir import AE_KIND, AE_SUBDIR, ae_checkpointer

    def save(folder, config):
        with training.Checkpointer(folder, kind=AE_KIND, config=config, skeleton=tdata.BODY_SIGNATURE,
                                   subdir=AE_SUBDIR) as ck:
            ck.save(types.SimpleNamespace(params={"w": jnp.ones(3)}, opt_state={}, step=jnp.asarray(5)))

    def check(folder, model):
        with ae_checkpointer(folder, model, read_only=True) as probe:
            probe.check_meta(probe.stored_meta())

    save(tmp_path / "new", TINY.model.autoencoder_dict())
    check(tmp_path / "new", dataclasses.replace(TINY.model, swap_similarity="scaled"))  # transformer side: shared
    with pytest.raises(CheckpointError, match="edge_frames"):
        check(tmp_path / "new", dataclasses.replace(TINY.model, edge_frames=0))
    old = {"name": "tiny", **TINY.model.to_dict(), "ae_window": 64, "ae_learning_rate": 1e-3}
    old.pop("swap_similarity")
    old["autoencoder"].pop("standardize")
    save(tmp_path / "old", json.loads(json.dumps(old)))
    check(tmp_path / "old", TINY.model)
    with pytest.raises(CheckpointError, match="standardize"):
        check(tmp_path / "old", dataclasses.replace(
            TINY.model, autoencoder=dataclasses.replace(TINY.model.autoencoder, standardize=True)))

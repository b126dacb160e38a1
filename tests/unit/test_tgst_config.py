"""TGST (paper 000) configs and sizes: parameter counts, layer shapes, presets, JSON round trip, overrides, and
configs/checkpoints written before a field existed."""

from __future__ import annotations

import dataclasses
import json

import jax
import jax.numpy as jnp
import pytest

from jaxgest.tgst import api
from jaxgest.tgst import data as tdata
from jaxgest.tgst.autoencoder import MotionAutoencoder
from jaxgest.tgst.config import Config, ModelConfig, preset
from jaxgest.tgst.transformer import StyleTransformer

from tgst_testing import TINY, param_count


def test_param_counts_paper():
    assert api.count_params("paper") == {"autoencoder": 23743, "transformer": 50240}


@pytest.mark.parametrize("variant", ["paper", "authors"])
@pytest.mark.parametrize("lns,expected", [(1, 50240), (2, 50496)])
def test_transformer_param_count_layernorms(variant, lns, expected):
    tcfg = dataclasses.replace(preset("paper").model.transformer, layernorms_per_block=lns, variant=variant)
    tok = jnp.zeros((1, 5, 64))
    shapes = jax.eval_shape(StyleTransformer(tcfg).init, jax.random.key(0), tok, tok)
    assert param_count(shapes) == expected


def test_autoencoder_layer_sizes_and_shapes():
    ae = MotionAutoencoder(preset("paper").model.autoencoder)
    shapes = jax.eval_shape(ae.init, jax.random.key(0), jnp.zeros((2, 64, 39)))["params"]
    sizes = {part: [param_count(shapes[part][f"conv_{i}"]) for i in range(3)]
             for part in ("encoder", "upper_decoder", "lower_decoder")}
    assert sizes == {"encoder": [2560, 6176, 1552], "upper_decoder": [1568, 6208, 2535],
                     "lower_decoder": [784, 1568, 792]}
    variables = {"params": shapes}
    z = jax.eval_shape(lambda v, x: ae.apply(v, x, method=MotionAutoencoder.encode), variables,
                       jnp.zeros((2, 64, 39)))
    assert z.shape == (2, 16, 16)
    (up, lo), _ = jax.eval_shape(ae.apply, variables, jnp.zeros((2, 64, 39)))
    assert up.shape == (2, 64, 39) and lo.shape == (2, 64, 24)


# The presets retired from the registry, as fit-motion + overrides (the experiment configs use these)
FIT_SMOOTH = {"train.autoencoder.expmap_branch": "principal", "train.autoencoder.trunk_weight": 1.0,
              "train.autoencoder.position_velocity_weight": 0.0, "train.autoencoder.lr_decay_steps": 6000,
              "train.autoencoder.steps": 1000}
FIT_PCA = {**FIT_SMOOTH, "model.autoencoder.linear_context": 0, "train.autoencoder.learning_rate": 1e-3,
           "train.autoencoder.init_velocity_weight": 0.0, "train.autoencoder.velocity_weight": 0.0,
           "train.autoencoder.steps": 6000}
FIT = {**FIT_PCA, "model.autoencoder.linear_path": False}


def retired(overrides: dict) -> Config:
    from jaxgest.tgst.trainer import apply_overrides

    return apply_overrides(preset("fit-motion"), overrides)


def test_config_json_round_trip_and_validation():
    from jaxgest.runtime.errors import JaxgestError
    from jaxgest.tgst.config import PRESETS

    assert list(PRESETS) == ["paper", "fit-motion", "tiny"]
    for name in PRESETS:
        cfg = preset(name)
        assert cfg.train.autoencoder.steps > 0 and cfg.train.transformer.steps > 0  # steps live in the config
        assert Config.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
        hash(cfg), hash(cfg.model)  # usable as jit static arguments
    with pytest.raises(JaxgestError, match="unknown TGST preset 'huge' \\(choose from paper, fit-motion, tiny\\)"):
        preset("huge")
    with pytest.raises(ValueError, match="block_size"):
        ModelConfig(transformer=dataclasses.replace(TINY.model.transformer, block_size=8))


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


def test_apply_overrides_reaches_sub_configs_and_rejects_bad_values():
    from jaxgest.runtime.errors import JaxgestError
    from jaxgest.tgst.trainer import apply_overrides

    cfg = apply_overrides(preset("fit-motion"), {"model.swap_similarity": "scaled",
                                                 "model.transformer.token_positions": "index",
                                                 "model.autoencoder.standardize": False,
                                                 "train.autoencoder.window": 32, "train.autoencoder.batch_size": 2})
    m = cfg.model
    assert m.swap_similarity == "scaled" and m.transformer.token_positions == "index"
    assert not m.autoencoder.standardize and m.edge_frames == 16
    assert cfg.train.autoencoder.window == 32 and cfg.train.autoencoder.batch_size == 2
    assert apply_overrides(TINY, None) == TINY
    with pytest.raises(JaxgestError, match="override"):
        apply_overrides(TINY, {"model.swap_similarity": "cosine"})
    with pytest.raises(JaxgestError, match="unknown TGST config field 'train.autoencoder.widht' "
                                           "\\(closest: train.autoencoder.window"):
        apply_overrides(TINY, {"train.autoencoder.widht": 3})
    with pytest.raises(JaxgestError, match="closest: model.swap_similarity"):  # one syntax: the dotted path
        apply_overrides(TINY, {"swap_similarity": "scaled"})
    with pytest.raises(JaxgestError, match="expected a float"):
        apply_overrides(TINY, {"train.autoencoder.learning_rate": "fast"})
    with pytest.raises(JaxgestError, match="trunk_weight must be >= 1"):
        apply_overrides(TINY, {"train.autoencoder.trunk_weight": 0.5})
    with pytest.raises(JaxgestError, match="a section"):
        apply_overrides(TINY, {"model.autoencoder": 3})
    with pytest.raises(JaxgestError, match="expmap_branch must be one of"):
        apply_overrides(TINY, {"train.autoencoder.expmap_branch": "nearest"})
    assert apply_overrides(TINY, {"train.autoencoder.expmap_branch": "rest"}).train.autoencoder.expmap_branch == "rest"
    # fields that must agree are changed together and checked once: a wider latent and its token width
    wide = apply_overrides(retired(FIT), {"model.autoencoder.encoder_channels": (64, 32, 32),
                                           "model.transformer.token_dim": 128})
    assert wide.model.autoencoder.latent_dim == 32 and wide.model.transformer.token_dim == 128
    with pytest.raises(JaxgestError, match="token_dim"):
        apply_overrides(retired(FIT), {"model.autoencoder.encoder_channels": (64, 32, 32)})


def test_checkpoints_check_only_the_model_config(tmp_path):
    """The autoencoder checkpoint checks the autoencoder's part of the model config: other training settings or
    transformer sizes share it, another autoencoder setting is a mismatch naming the field. A checkpoint of the
    flat layout of older versions (whole config, fields it predates absent) matches the same model."""
    import types

    from jaxgest.runtime import training
    from jaxgest.runtime.errors import CheckpointError
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
    # an autoencoder checkpoint written before latent_activation / linear_path / linear_context existed is read
    # with their older behaviour (GELU latent, no linear path), so it loads for those models and no other
    before = TINY.model.autoencoder_dict()
    for field in ("latent_activation", "linear_path", "linear_context"):
        before["autoencoder"].pop(field)
    save(tmp_path / "before", json.loads(json.dumps(before)))
    check(tmp_path / "before", TINY.model)
    with pytest.raises(CheckpointError, match="linear_path"):
        check(tmp_path / "before", dataclasses.replace(
            TINY.model, autoencoder=dataclasses.replace(TINY.model.autoencoder, linear_path=True)))
    fit_pca = retired(FIT_PCA).model  # a fit-pca checkpoint of the version before linear_context
    no_context = fit_pca.autoencoder_dict()
    no_context["autoencoder"].pop("linear_context")
    save(tmp_path / "fit-pca", json.loads(json.dumps(no_context)))
    check(tmp_path / "fit-pca", fit_pca)
    with pytest.raises(CheckpointError, match="linear_context"):
        check(tmp_path / "fit-pca", retired(FIT_SMOOTH).model)


def test_fit_pca_preset_is_fit_with_the_linear_path_and_paper_stays_the_papers():
    fit, fp, paper = retired(FIT), retired(FIT_PCA), preset("paper")
    assert not paper.model.autoencoder.linear_path and paper.model.autoencoder.latent_activation
    assert fp.model.autoencoder == dataclasses.replace(fit.model.autoencoder, linear_path=True)
    assert dataclasses.replace(fp, model=fit.model) == fit
    assert fp.train.autoencoder.pca_init
    assert api.count_params(fp)["autoencoder"] - api.count_params(fit)["autoencoder"] == \
        (4 * 39 * 16 + 16) + (16 * 4 * 39 + 4 * 39) + (16 * 4 * 24 + 4 * 24)
    assert Config.from_dict(json.loads(json.dumps(fp.to_dict()))) == fp


def test_fit_smooth_preset_is_fit_with_the_lapped_linear_path_and_leaves_the_others_unchanged():
    fit, fp, fs = retired(FIT), retired(FIT_PCA), retired(FIT_SMOOTH)
    assert fs.model.autoencoder == dataclasses.replace(fit.model.autoencoder, linear_path=True, linear_context=1)
    assert fs.model == dataclasses.replace(fit.model, autoencoder=fs.model.autoencoder)
    assert fs.train.autoencoder.init_velocity_weight > 0 and fs.train.autoencoder.pca_init
    assert fp.model.autoencoder.linear_context == 0 and fp.train.autoencoder.velocity_weight == 0
    assert fit.train.autoencoder.velocity_weight == 0 and fit.train.autoencoder.init_velocity_weight == 0
    # lapped: encoder kernel 3 blocks of 4 frames, decoders over 3 latent frames
    assert api.count_params(fs)["autoencoder"] - api.count_params(fit)["autoencoder"] == \
        (12 * 39 * 16 + 16) + (3 * 16 * 4 * 39 + 4 * 39) + (3 * 16 * 4 * 24 + 4 * 24)
    assert Config.from_dict(json.loads(json.dumps(fs.to_dict()))) == fs


def test_fit_motion_preset_is_fit_smooth_with_its_training_options_and_every_preset_has_default_steps():
    from jaxgest.runtime.errors import JaxgestError
    from jaxgest.tgst.config import PRESETS

    fs, fm = retired(FIT_SMOOTH), preset("fit-motion")
    assert fm.model == fs.model  # the same network: only how it is trained differs
    assert fm.train.transformer == fs.train.transformer
    assert fm.train.autoencoder == dataclasses.replace(
        fs.train.autoencoder, expmap_branch="rest", trunk_weight=4.0, position_velocity_weight=0.15,
        lr_decay_steps=500, steps=500)
    assert fs.train.autoencoder.expmap_branch == "principal" and fs.train.autoencoder.trunk_weight == 1.0
    # the paper preset keeps the paper's exp-maps; tiny (tests, demo) trains on the rest branch: its synthetic
    # rig's upper legs also rest at pi
    assert preset("paper").train.autoencoder.expmap_branch == "principal"
    assert preset("tiny").train.autoencoder.expmap_branch == "rest"
    assert Config.from_dict(json.loads(json.dumps(fm.to_dict()))) == fm
    assert all(preset(n).name == n for n in PRESETS)
    steps = {n: (preset(n).train.autoencoder.steps, preset(n).train.transformer.steps) for n in PRESETS}
    assert steps == {"paper": (10_000, 10_000), "fit-motion": (500, 10_000), "tiny": (200, 200)}
    with pytest.raises(JaxgestError, match="fit-motion"):
        preset("fit-moton")

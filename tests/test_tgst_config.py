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
from jaxgest.tgst.config import TGSTConfig, config_from_dict, get_config
from jaxgest.tgst.transformer import StyleTransformer

from tgst_testing import TINY, param_count


def test_param_counts_paper():
    assert api.count_params("paper") == {"autoencoder": 23743, "transformer": 50240}


@pytest.mark.parametrize("variant", ["paper", "authors"])
@pytest.mark.parametrize("lns,expected", [(1, 50240), (2, 50496)])
def test_transformer_param_count_layernorms(variant, lns, expected):
    tcfg = dataclasses.replace(get_config("paper").transformer, layernorms_per_block=lns, variant=variant)
    tok = jnp.zeros((1, 5, 64))
    shapes = jax.eval_shape(StyleTransformer(tcfg).init, jax.random.PRNGKey(0), tok, tok)
    assert param_count(shapes) == expected


def test_autoencoder_layer_sizes_and_shapes():
    ae = MotionAutoencoder(get_config("paper").autoencoder)
    shapes = jax.eval_shape(ae.init, jax.random.PRNGKey(0), jnp.zeros((2, 64, 39)))["params"]
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


def test_config_json_round_trip_and_validation():
    from jaxgest.tgst.config import PRESETS
    from jaxgest.tgst.train import DEFAULT_STEPS

    assert set(PRESETS) == set(DEFAULT_STEPS)
    for name in PRESETS:
        cfg = get_config(name)
        assert config_from_dict(json.loads(json.dumps(dataclasses.asdict(cfg)))) == cfg
        hash(cfg)  # usable as a jit static argument
    with pytest.raises(ValueError):
        get_config("huge")
    with pytest.raises(ValueError, match="block_size"):
        TGSTConfig(transformer=dataclasses.replace(TINY.transformer, block_size=8))


def test_stored_config_without_new_fields_keeps_old_behaviour():
    from jaxgest.tgst.config import with_stored_defaults

    new = get_config("paper")
    old = dataclasses.asdict(new)
    for k in ("edge_frames", "swap_similarity", "ae_lr_schedule", "ae_lr_decay_steps", "ae_sampling"):
        old.pop(k)
    old["transformer"].pop("token_positions")
    old["autoencoder"].pop("standardize")
    cfg = with_stored_defaults(new, old)
    assert cfg.edge_frames == 0 and cfg.swap_similarity == "dot" and cfg.transformer.token_positions == "index"
    assert with_stored_defaults(new, dataclasses.asdict(new)) == new


def test_apply_overrides_reaches_sub_configs_and_rejects_bad_values():
    from jaxgest.errors import JaxgestError
    from jaxgest.tgst.train import apply_overrides

    cfg = apply_overrides(get_config("fit"), {"swap_similarity": "scaled", "transformer.token_positions": "index",
                                              "autoencoder.standardize": False})
    assert cfg.swap_similarity == "scaled" and cfg.transformer.token_positions == "index"
    assert not cfg.autoencoder.standardize and cfg.edge_frames == 16
    assert apply_overrides(TINY, None) == TINY
    with pytest.raises(JaxgestError, match="override"):
        apply_overrides(TINY, {"swap_similarity": "cosine"})


def test_checkpoint_of_an_older_version_still_matches(tmp_path):
    """A checkpoint whose config predates the added fields resumes/loads with a config that has them at their
    old defaults; another value of such a field is still reported as a mismatch."""
    import types

    from jaxgest import training
    from jaxgest.errors import CheckpointError
    from jaxgest.tgst.config import with_stored_defaults
    from jaxgest.tgst.train import AE_IGNORED, AE_KIND, AE_SUBDIR, ae_checkpointer

    old = dataclasses.asdict(TINY)
    for k in ("edge_frames", "swap_similarity", "ae_lr_schedule", "ae_lr_decay_steps", "ae_sampling", "ae_mirror"):
        old.pop(k)
    old["autoencoder"].pop("standardize")
    old["transformer"].pop("token_positions")
    ck = training.Checkpointer(tmp_path, kind=AE_KIND, config=old, skeleton=tdata.BODY_SIGNATURE, subdir=AE_SUBDIR,
                               ignore=AE_IGNORED)
    ck.save(types.SimpleNamespace(params={"w": jnp.ones(3)}, opt_state={}, step=jnp.asarray(5)))
    ck.close()
    cfg = with_stored_defaults(get_config("tiny"), old)  # edge_frames 0 etc.: the old behaviour
    assert cfg.edge_frames == 0 and cfg.ae_mirror
    probe = ae_checkpointer(tmp_path, cfg, read_only=True)
    probe.check_meta(probe.stored_meta())  # no mismatch
    probe.close()
    probe = ae_checkpointer(tmp_path, dataclasses.replace(cfg, ae_mirror=False), read_only=True)
    with pytest.raises(CheckpointError, match="ae_mirror"):
        probe.check_meta(probe.stored_meta())
    probe.close()

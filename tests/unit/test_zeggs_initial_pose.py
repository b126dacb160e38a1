"""ZeroEGGS initial-pose experiment options (not the paper: ``initial_pose_shuffle``, ``initial_pose_source``,
``initial_pose_mask_seconds``): which start each row gets, frame weights, and that each option changes only
what it says."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgest.zeggs import losses, steps
from jaxgest.zeggs.config import Config, preset
from jaxgest.zeggs.model import init_params
from zeggs_testing import zeggs_batch as _batch

TINY = preset("tiny")
CFG = TINY.model


def test_initial_poses_own_or_previous_row():
    """initial_pose_shuffle: probability 0 is the paper (each row's own first frame); 1 takes the previous
    row's; in between each row is one of the two, about that often; a batch of one keeps its own."""
    rng = np.random.default_rng(0)
    pose = jnp.asarray(rng.normal(size=(400, 5, 3)), jnp.float32)
    key = jax.random.key(3)
    own, prev = np.asarray(pose[:, 0]), np.roll(np.asarray(pose[:, 0]), 1, axis=0)
    np.testing.assert_array_equal(steps.initial_poses(pose, key, 0.0), own)
    np.testing.assert_array_equal(steps.initial_poses(pose, key, 1.0), prev)
    got = np.asarray(steps.initial_poses(pose, key, 0.5))
    is_own, is_prev = (got == own).all(1), (got == prev).all(1)
    assert (is_own | is_prev).all()
    assert 0.4 < is_prev.mean() < 0.6, is_prev.mean()
    np.testing.assert_array_equal(steps.initial_poses(pose[:1], key, 1.0), own[:1])
    with pytest.raises(ValueError, match="initial_pose_shuffle"):
        Config().override(initial_pose_shuffle=1.5)


def test_initial_pose_mean_source_and_frame_weight():
    """initial_pose_source="mean" replaces a swapped row's start by zeros (the normalised mean pose), with the
    swaps of initial_pose_swaps; the frame weight is 0 on the first frames of swapped rows only, keeps two."""
    rng = np.random.default_rng(1)
    pose = jnp.asarray(rng.normal(size=(64, 5, 3)), jnp.float32)
    key = jax.random.key(4)
    swap = np.asarray(steps.initial_pose_swaps(key, 0.5, 64))
    got = np.asarray(steps.initial_poses(pose, key, 0.5, "mean"))
    np.testing.assert_array_equal(got[swap], 0.0)
    np.testing.assert_array_equal(got[~swap], np.asarray(pose[:, 0])[~swap])
    assert 0 < swap.sum() < 64
    w = np.asarray(steps.initial_pose_frame_weight(jnp.asarray(swap), 10, 3))
    np.testing.assert_array_equal(w[swap, :3], 0.0)
    np.testing.assert_array_equal(w[swap, 3:], 1.0)
    np.testing.assert_array_equal(w[~swap], 1.0)
    assert steps.initial_pose_frame_weight(jnp.asarray(swap), 10, 0) is None
    assert np.asarray(steps.initial_pose_frame_weight(jnp.asarray(swap), 10, 50))[swap].sum(1).min() == 2
    with pytest.raises(ValueError, match="initial_pose_source"):
        Config().override(initial_pose_source="median")
    with pytest.raises(ValueError, match="initial_pose_mask_seconds"):
        Config().override(initial_pose_mask_seconds=-1.0)


def test_weighted_mae_is_the_mean_over_kept_frames():
    """losses.mae with frame weights: all ones is the plain MAE; 0/1 weights are the MAE of the kept frames."""
    rng = np.random.default_rng(2)
    a, b = (jnp.asarray(rng.normal(size=(3, 7, 4, 2)), jnp.float32) for _ in range(2))
    np.testing.assert_allclose(losses.mae(a, b, jnp.ones((3, 7))), losses.mae(a, b), rtol=1e-6)
    w = np.ones((3, 7), np.float32)
    w[:, :3] = 0.0
    np.testing.assert_allclose(losses.mae(a, b, jnp.asarray(w)), losses.mae(a[:, 3:], b[:, 3:]), rtol=1e-6)


def _eval_loss(seed: int, key_seed: int):
    """``loss(cfg, batch) -> (B,)`` of deterministic loss_terms at step 100 with fresh tiny parameters (own
    parameters: the module fixture's are donated by the train-step test)."""
    params = init_params(CFG, jax.random.key(seed))
    stats = steps.pose_stats(CFG)
    key = jax.random.key(key_seed)

    def loss(cfg, b):
        return np.asarray(steps.loss_terms(params, b, key, 100, cfg=cfg, pose_mean=stats["mean"],
                                           pose_std=stats["std"], deterministic=True)["loss"])

    return loss


def test_initial_pose_mask_leaves_out_the_start_of_swapped_rows():
    """With the mask the loss of a swapped row ignores its first frames: at shuffle 0 it changes nothing
    (exactly the paper's step), at shuffle 1 it changes the loss, and the masked loss does not depend on the
    target's first frames (perturbing them leaves it equal) while the unmasked one does."""
    loss, batch = _eval_loss(6, 2), _batch()
    frames = 4
    secs = frames / CFG.fps
    np.testing.assert_array_equal(loss(TINY.override(initial_pose_mask_seconds=secs), batch), loss(TINY, batch))
    masked = TINY.override(initial_pose_shuffle=1.0, initial_pose_mask_seconds=secs)
    plain = TINY.override(initial_pose_shuffle=1.0)
    assert not np.allclose(loss(masked, batch), loss(plain, batch))
    pose = np.array(batch["pose"])
    pose[:, 1:frames] += 0.5  # frame 0 (the start) kept
    bumped = dict(batch, pose=pose)
    np.testing.assert_allclose(loss(masked, bumped), loss(masked, batch), rtol=1e-5)
    assert not np.allclose(loss(plain, bumped), loss(plain, batch))
    pose = np.array(batch["pose"])
    pose[:, frames] += 0.5  # the first kept frame counts
    kept = dict(batch, pose=pose)
    assert (np.abs(loss(masked, kept) - loss(masked, batch)) > 1e-4).all()


def test_initial_pose_mask_and_start_agree_on_the_swapped_rows():
    """At shuffle 0.5 with the mask, the rows the draw keeps have exactly the paper's per-row loss (own start,
    no mask) and the swapped rows do not: the start and the mask come from one draw (initial_pose_swaps on
    the step key's fold, as loss_terms makes it)."""
    loss, batch = _eval_loss(7, 3), _batch(B=16, seed=3)
    swap = np.asarray(steps.initial_pose_swaps(jax.random.fold_in(jax.random.key(3), 0x1_5E), 0.5, 16))
    assert 0 < swap.sum() < 16
    base = loss(TINY, batch)
    got = loss(TINY.override(initial_pose_shuffle=0.5, initial_pose_mask_seconds=3 / CFG.fps), batch)
    np.testing.assert_allclose(got[~swap], base[~swap], rtol=1e-5)
    assert (np.abs(got[swap] - base[swap]) > 1e-4 * np.abs(base[swap])).all()


def test_initial_pose_shuffle_changes_only_the_generators_start():
    """The shuffle draws from its own key: at 0 the loss is the paper's step exactly; at 1 on a batch whose
    rows are equal (rolling them changes nothing) it is exactly that too, and on distinct rows it differs.
    """
    loss, batch = _eval_loss(5, 1), _batch()
    base = loss(TINY, batch)
    np.testing.assert_array_equal(loss(TINY.override(initial_pose_shuffle=0.0), batch), base)
    assert not np.allclose(loss(TINY.override(initial_pose_shuffle=1.0), batch), base)
    same = {k: jnp.broadcast_to(v[:1], v.shape) for k, v in batch.items()}
    np.testing.assert_array_equal(loss(TINY.override(initial_pose_shuffle=1.0), same), loss(TINY, same))


def test_presets_initial_pose_defaults():
    """The ``small`` preset starts a fifth of its rows from the mean pose (adopted on five seeds in
    experiments/zeggs_synthetic); the ``paper`` and ``tiny`` presets keep the paper's own first pose, and a
    workdir config of an earlier version (no such fields) reads back as the paper's."""
    small = preset("small").train
    assert (small.initial_pose_shuffle, small.initial_pose_source) == (0.2, "mean")
    assert small.initial_pose_mask_seconds == 0.0
    for name in ("paper", "tiny"):
        assert preset(name).train.initial_pose_shuffle == 0.0
    d = preset("small").to_dict()
    d["train"] = {k: v for k, v in d["train"].items() if not k.startswith("initial_pose")}
    old = Config.from_dict(d)
    assert (old.train.initial_pose_shuffle, old.train.initial_pose_source) == (0.0, "row")

"""TGST autoencoder, lapped linear path (``AutoencoderConfig.linear_context``) and the velocity loss term: the
closed-form start is the least-squares linear autoencoder it claims to be, and a smooth input goes through it
without the block-boundary jumps of the block PCA."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgest.tgst import baselines
from jaxgest.tgst import data as tdata
from jaxgest.tgst.autoencoder import (MotionAutoencoder, _context_features, expmap_reconstruction_loss,
                                      expmap_velocity_loss, init_linear_path, lapped_decoder_fit)
from jaxgest.tgst.model import init_params

from tgst_testing import CFG, random_like, smooth_motion


@pytest.fixture(scope="module")
def clips():
    """40 smooth training clips (upper, lower) of 96 frames: enough blocks for the least-squares fits."""
    ups = [np.asarray(smooth_motion(20 + i, 1, 96, 39)[0]) for i in range(40)]
    los = [np.asarray(smooth_motion(80 + i, 1, 96, 24)[0]) for i in range(40)]
    return ups, los


def _cfg(context, standardize=True):
    ae = dataclasses.replace(CFG.autoencoder, linear_path=True, linear_context=context, standardize=standardize)
    return dataclasses.replace(CFG, autoencoder=ae)


def _start(cfg, ups, los, velocity_weight):
    p = random_like(jax.eval_shape(lambda k: init_params(cfg, k), jax.random.key(0)))["autoencoder"]
    if cfg.autoencoder.standardize:
        stats = tdata.channel_stats(tdata.BodyData(ups, los, ups, los, [str(i) for i in range(len(ups))], 60.0))
        p = dict(p, **{k: jnp.asarray(v) for k, v in stats.items()})
    return init_linear_path(p, cfg.autoencoder, ups, los, velocity_weight=velocity_weight)


def _jump_ratio(y):
    """Mean |change| across block boundaries (t mod 4 = 3) over the mean |change| inside blocks."""
    d = np.abs(np.diff(np.asarray(y), axis=0)).sum(1)
    ph = np.arange(len(d)) % 4
    return d[ph == 3].mean() / d[ph != 3].mean()


def test_lapped_parameters_have_the_stated_shapes():
    lin = jax.eval_shape(lambda k: init_params(_cfg(1, False), k), jax.random.key(0))["autoencoder"]
    assert lin["linear_encoder"]["kernel"].shape == (12, 39, 16)  # (2c + 1) blocks of 4 frames
    assert lin["linear_upper"]["kernel"].shape == (3, 16, 4 * 39)  # latent frames t-1 .. t+1 -> block t
    assert lin["linear_lower"]["kernel"].shape == (3, 16, 4 * 24)


def test_lapped_decoder_fit_is_the_least_squares_solution():
    """Normal equations vs an explicit design matrix (frame rows and weighted difference rows) and lstsq."""
    rng = np.random.default_rng(0)
    codes = [rng.normal(size=(t, 3)) for t in (7, 9)]
    targets = [rng.normal(size=(4 * len(z), 2)) for z in codes]
    r, c, vw = 4, 1, 2.5
    w = lapped_decoder_fit(codes, targets, frames=r, context=c, velocity_weight=vw)
    rows, ys = [], []
    for z, x in zip(codes, targets):
        f = _context_features(z, c)
        p = f.shape[1]

        def pred_row(frame):  # the row of x_hat[frame] in the unknowns (frame slot j, features of block t)
            row = np.zeros(r * p)
            t, j = divmod(frame, r)
            row[j * p:(j + 1) * p] = f[t]
            return row
        for i in range(len(x)):
            rows.append(pred_row(i)), ys.append(x[i])
        for i in range(len(x) - 1):
            rows.append(np.sqrt(vw) * (pred_row(i + 1) - pred_row(i))), ys.append(np.sqrt(vw) * (x[i + 1] - x[i]))
    ref = np.linalg.lstsq(np.array(rows), np.array(ys), rcond=None)[0]
    np.testing.assert_allclose(w.reshape(-1, 2), ref, atol=1e-5)  # (a 1e-8 relative ridge in the fit)


@pytest.mark.parametrize("standardize", [True, False])
def test_lapped_start_reproduces_its_closed_form_linear_autoencoder(clips, standardize):
    """At step 0 the network (conv stacks' last layers zeroed) is the block-PCA encoder plus the least-squares
    lapped decoders, in raw exp-map units whatever the standardisation; on its training clips it is at least
    as good as the block PCA it extends (the block decoder is one of its candidates)."""
    ups, los = clips
    cfg = _cfg(1, standardize)
    p = _start(cfg, ups, los, velocity_weight=0.0)
    pca = baselines.block_pca_fit(ups, components=16, frames=4)
    codes = [(u.reshape(-1, 156) - pca["mean"]) @ pca["basis"].T for u in ups]
    w_up = lapped_decoder_fit(codes, ups, frames=4, context=1)
    w_lo = lapped_decoder_fit(codes, los, frames=4, context=1)
    (up, lo), _ = jax.jit(MotionAutoencoder(cfg.autoencoder).apply)({"params": p}, jnp.asarray(np.stack(ups[:3])))
    for i in range(3):
        f = _context_features(codes[i], 1)
        np.testing.assert_allclose(np.asarray(up[i]), np.einsum("tp,jpc->tjc", f, w_up).reshape(-1, 39), atol=2e-4)
        np.testing.assert_allclose(np.asarray(lo[i]), np.einsum("tp,jpc->tjc", f, w_lo).reshape(-1, 24), atol=2e-4)
    (up_all, _), _ = jax.jit(MotionAutoencoder(cfg.autoencoder).apply)({"params": p}, jnp.asarray(np.stack(ups)))
    err = np.mean((np.asarray(up_all) - np.stack(ups)) ** 2)
    err_pca = np.mean([(baselines.block_pca_reconstruct(pca, u) - u) ** 2 for u in ups])
    assert err <= err_pca * (1 + 1e-4)


def test_smooth_input_goes_through_the_lapped_path_without_block_boundary_jumps(clips):
    """A smooth clip not in the training set: the block PCA (``linear_context=0``, the ``fit-pca`` start)
    changes several times more across block boundaries than inside blocks; the lapped start does not."""
    ups, los = clips
    x = jnp.asarray(smooth_motion(99, 1, 96, 39))
    assert _jump_ratio(x[0]) < 1.2  # the input itself moves evenly
    ratios = {}
    for context, vw in ((0, 0.0), (1, 1.0)):
        cfg = _cfg(context)
        p = _start(cfg, ups, los, velocity_weight=vw)
        (up, _), _ = MotionAutoencoder(cfg.autoencoder).apply({"params": p}, x)
        ratios[context] = _jump_ratio(up[0])
    assert ratios[0] > 4.0, ratios
    assert ratios[1] < 2.0, ratios


def test_velocity_loss_is_the_reconstruction_loss_of_the_frame_differences():
    x = smooth_motion(3, 2, 32, 39)
    y = x + 0.1  # a constant offset: wrong poses, right motion
    assert float(jnp.max(expmap_velocity_loss(y, x))) < 1e-6 < float(jnp.min(expmap_reconstruction_loss(y, x)))
    jitter = x.at[:, ::4].add(0.05)  # a jump every 4 frames
    np.testing.assert_allclose(np.asarray(expmap_velocity_loss(jitter, x)),
                               np.asarray(expmap_reconstruction_loss(jnp.diff(jitter, axis=1), jnp.diff(x, axis=1))),
                               rtol=1e-6)
    assert float(jnp.min(expmap_velocity_loss(jitter, x))) > 0.01

"""Conv1d motion autoencoder of tokenized gesture style transfer and its reconstruction losses.

Layout is NWC: ``(batch, frames, channels)``. The encoder sees only the 13 upper-body joints (39 exp-map
channels) and two decoders restore the upper (39) and the lower (24) body from the same latents.

References: Kuriyama et al. 2022, §3.2 and App. A; the authors' public code for the loss.
"""

from __future__ import annotations

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.motion import body, kinematics
from jaxgest.motion.rotations import angular_error_rad  # noqa: F401 (re-exported; moved below baselines)
from jaxgest.nn import gelu_exact, safe_norm
from jaxgest.tgst import baselines
from jaxgest.tgst.config import POSITION_VELOCITY_JOINTS, AutoencoderConfig


def _pytorch_padding(kernel: int) -> tuple[tuple[int, int]]:
    """``padding=k // 2`` on both sides, like ``torch.nn.Conv1d(padding=k // 2)``: ceil(F / stride) out."""
    return ((kernel // 2, kernel // 2),)


def upsample_linear(x: jax.Array, factor: int) -> jax.Array:
    """Linear upsampling along frames ``(batch, F, ch) -> (batch, factor * F, ch)``.

    Same as ``torch.nn.Upsample(mode="linear", align_corners=False)`` (half-pixel centres, edge frames
    clamped) and as ``jax.image.resize(..., "linear")``. The x2 case is written out (out[2k] = 3/4 x[k] +
    1/4 x[k-1], out[2k+1] = 3/4 x[k] + 1/4 x[k+1], clamped at the ends): it compiles and runs much faster
    than the general resize. References: Kuriyama et al. 2022, App. A.
    """
    if factor == 1:
        return x
    b, f, c = x.shape
    if factor != 2:
        return jax.image.resize(x, (b, f * factor, c), method="linear")
    prev = jnp.concatenate([x[:, :1], x[:, :-1]], axis=1)
    nxt = jnp.concatenate([x[:, 1:], x[:, -1:]], axis=1)
    even, odd = 0.75 * x + 0.25 * prev, 0.75 * x + 0.25 * nxt
    return jnp.stack([even, odd], axis=2).reshape(b, 2 * f, c)


class _ConvStack(nn.Module):
    """Conv1d layers, optional linear upsampling before each, GELU after each (optionally not the last)."""

    features: tuple[int, ...]
    kernels: tuple[int, ...]
    strides: tuple[int, ...]
    upsample: tuple[int, ...]
    final_activation: bool

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        n = len(self.features)
        for i, (feat, k, s, up) in enumerate(zip(self.features, self.kernels, self.strides, self.upsample)):
            x = upsample_linear(x, up)
            pad = _pytorch_padding(k)
            x = nn.Conv(feat, kernel_size=(k,), strides=(s,), padding=pad, name=f"conv_{i}")(x)
            if i < n - 1 or self.final_activation:
                x = gelu_exact(x)
        return x


class MotionAutoencoder(nn.Module):
    """Encoder 39 -> 64 -> 32 -> 16 (strides 1, 2, 2); decoders 16 -> 32 -> 64 -> 39 and 16 -> 16 -> 32 -> 24.

    ``encode``: ``(batch, F, 39) -> (batch, ceil(F / 4), 16)``; ``decode_upper`` / ``decode_lower``:
    ``(batch, T, 16) -> (batch, 4T, 39 | 24)``. 23,743 parameters with the paper preset. The decoders'
    ``ConvTranspose1d(k=3, padding=1, stride=1)`` of the authors' code is a same-size convolution with a
    flipped kernel, i.e. an ordinary ``padding=1`` convolution here (same parameter count).
    ``__call__`` (used for ``init``) returns ``((upper, lower), {"latents": z})``.
    ``config.latent_activation=False`` drops the GELU on the latent (the encoder's last conv is linear).
    ``config.linear_path`` adds a block-linear encoder (``linear_encoder``: a conv of kernel = stride =
    ``time_reduction``) to the latent and a linear map of each latent frame to its block of frames
    (``linear_upper``, ``linear_lower``) to each decoder's output (standardised units); :func:`init_linear_path`
    sets them to the training data's block PCA. ``config.linear_context`` = c > 0 makes the path lapped: the
    encoder reads c blocks on each side as well (kernel ``(2c + 1) r``, stride r) and each decoder maps latent
    frames t - c .. t + c to block t (a transposed conv of kernel ``(2c + 1) r``, stride r), so consecutive
    blocks share latents and the output need not jump at block boundaries.
    ``config.standardize`` adds the per-channel mean and std of the training data as four frozen parameter
    arrays (``upper_mean``/``upper_std`` (39), ``lower_mean``/``lower_std`` (24); gradients stopped, so Adam
    leaves them unchanged): inputs are standardised and outputs de-standardised (not in the paper).
    References: Kuriyama et al. 2022, App. A.
    """

    config: AutoencoderConfig

    def setup(self):
        c = self.config
        n_enc = len(c.encoder_channels)
        self.encoder = _ConvStack(
            features=tuple(c.encoder_channels),
            kernels=tuple(c.encoder_kernels),
            strides=tuple(c.encoder_strides),
            upsample=(1,) * n_enc,
            final_activation=c.latent_activation,
        )

        def decoder(hidden, out: int) -> _ConvStack:  # the two decoders differ only in their widths
            return _ConvStack(features=tuple(hidden) + (out,), kernels=tuple(c.decoder_kernels),
                              strides=(1,) * len(c.decoder_kernels), upsample=tuple(c.decoder_upsample),
                              final_activation=False)

        self.upper_decoder = decoder(c.upper_decoder_channels, c.upper_channels)
        self.lower_decoder = decoder(c.lower_decoder_channels, c.lower_channels)
        if c.linear_path:  # block-linear path (not in the paper; see AutoencoderConfig.linear_path)
            r, n = c.time_reduction, 2 * c.linear_context + 1
            self.linear_encoder = nn.Conv(c.latent_dim, kernel_size=(n * r,), strides=(r,), padding="VALID")
            if c.linear_context:  # lapped: each output block from latent frames t - c .. t + c
                self.linear_upper = nn.Conv(r * c.upper_channels, kernel_size=(n,), padding="VALID")
                self.linear_lower = nn.Conv(r * c.lower_channels, kernel_size=(n,), padding="VALID")
            else:  # the block path of ``fit-pca`` checkpoints (Dense parameters)
                self.linear_upper = nn.Dense(r * c.upper_channels)
                self.linear_lower = nn.Dense(r * c.lower_channels)

        if c.standardize:  # frozen data statistics (set by training, never updated: stop_gradient below)
            zeros, ones = nn.initializers.zeros, nn.initializers.ones
            self.upper_mean = self.param("upper_mean", zeros, (c.upper_channels,))
            self.upper_std = self.param("upper_std", ones, (c.upper_channels,))
            self.lower_mean = self.param("lower_mean", zeros, (c.lower_channels,))
            self.lower_std = self.param("lower_std", ones, (c.lower_channels,))

    def _stats(self, part: str):
        sg = jax.lax.stop_gradient
        return sg(getattr(self, f"{part}_mean"))[None, None], sg(getattr(self, f"{part}_std"))[None, None]

    def encode(self, upper: jax.Array) -> jax.Array:
        """Upper-body exp-maps ``(batch, F, 39)`` -> latents ``(batch, ceil(F / 4), 16)``."""
        chex.assert_rank(upper, 3)
        chex.assert_axis_dimension(upper, 2, self.config.upper_channels)
        if self.config.standardize:
            mean, std = self._stats("upper")
            upper = (upper - mean) / std
        z = self.encoder(upper)
        if self.config.linear_path:  # blocks of r frames (the end replicated to a whole block) and, lapped, c
            r, cr = self.config.time_reduction, self.config.linear_context * self.config.time_reduction
            # replicated blocks of context on each side: one latent frame per block either way
            x = jnp.pad(upper, ((0, 0), (cr, cr + (-upper.shape[1] % r)), (0, 0)), mode="edge")
            z = z + self.linear_encoder(x)
        return z

    def _decode(self, decoder, part: str, z: jax.Array) -> jax.Array:
        chex.assert_rank(z, 3)
        y = decoder(z)
        if self.config.linear_path:  # latent frames t - c .. t + c (edge-replicated) -> block t of r frames
            b, t, _ = z.shape
            c = self.config.linear_context
            zc = jnp.pad(z, ((0, 0), (c, c), (0, 0)), mode="edge") if c else z
            y = y + getattr(self, f"linear_{part}")(zc).reshape(b, t * self.config.time_reduction, -1)
        if self.config.standardize:
            mean, std = self._stats(part)
            y = mean + std * y
        return y

    def decode_upper(self, z: jax.Array) -> jax.Array:
        """Latents ``(batch, T, 16)`` -> upper-body exp-maps ``(batch, 4T, 39)``."""
        return self._decode(self.upper_decoder, "upper", z)

    def decode_lower(self, z: jax.Array) -> jax.Array:
        """Latents ``(batch, T, 16)`` -> lower-body exp-maps ``(batch, 4T, 24)``."""
        return self._decode(self.lower_decoder, "lower", z)

    def __call__(self, upper: jax.Array):
        z = self.encode(upper)
        return (self.decode_upper(z), self.decode_lower(z)), {"latents": z}


def _context_features(z: np.ndarray, c: int) -> np.ndarray:
    """Latent frames ``(T, d)`` -> ``(T, (2c + 1) d + 1)``: frames t - c .. t + c (edge-replicated) and a 1."""
    t = len(z)
    zp = np.pad(z, ((c, c), (0, 0)), mode="edge")
    return np.concatenate([zp[k:k + t] for k in range(2 * c + 1)] + [np.ones((t, 1))], axis=1)


def lapped_decoder_fit(codes, targets, *, frames: int, context: int, velocity_weight: float = 0.0) -> np.ndarray:
    """Least-squares linear decoder from latent frames t - c .. t + c (and a bias) to block t of frames.

    codes: per clip ``(T_i, d)``; targets: per clip ``(T_i * frames, C)``. Minimises the squared error of every
    frame plus ``velocity_weight`` times the squared error of every frame-to-frame difference (inside blocks
    and across block boundaries, where a block decoder jumps). Returns ``W`` ``(frames, (2c + 1) d + 1, C)``:
    frame j of block t is ``features_t @ W[j]`` (:func:`_context_features`). Closed form (normal equations).
    """
    r = frames
    p = (2 * context + 1) * codes[0].shape[1] + 1
    a = np.zeros((r * p, r * p))
    b = np.zeros((r * p, targets[0].shape[1]))

    def add(rows: np.ndarray, y: np.ndarray, w: float):
        a[...] += w * rows.T @ rows
        b[...] += w * rows.T @ y

    for z, x in zip(codes, targets):
        f = _context_features(np.asarray(z, np.float64), context)
        t = len(f)
        x = np.asarray(x, np.float64).reshape(t, r, -1)
        for j in range(r):  # frame j of every block: features in slot j
            a[j * p:(j + 1) * p, j * p:(j + 1) * p] += f.T @ f
            b[j * p:(j + 1) * p] += f.T @ x[:, j]
        if velocity_weight:
            for j in range(r - 1):  # x[j + 1] - x[j] inside a block
                rows = np.zeros((t, r * p))
                rows[:, (j + 1) * p:(j + 2) * p], rows[:, j * p:(j + 1) * p] = f, -f
                add(rows, x[:, j + 1] - x[:, j], velocity_weight)
            rows = np.zeros((t - 1, r * p))  # first frame of block t + 1 minus last frame of block t
            rows[:, :p], rows[:, (r - 1) * p:] = f[1:], -f[:-1]
            add(rows, x[1:, 0] - x[:-1, r - 1], velocity_weight)
    w = np.linalg.solve(a + 1e-8 * np.trace(a) / len(a) * np.eye(len(a)), b)
    return w.reshape(r, p, -1)


def init_linear_path(params: dict, config: AutoencoderConfig, uppers, lowers, *, velocity_weight: float = 0.0) -> dict:
    """``params`` with the linear path set to a linear autoencoder fitted to the clips and the conv stacks'
    last layers zeroed, so training starts at that linear reconstruction and the convs learn the remainder.

    Encoder: the block PCA of ``uppers`` (:func:`jaxgest.tgst.baselines.block_pca_fit`, ``latent_dim``
    components per ``time_reduction`` frames, raw exp-map units; with ``linear_context`` > 0 the context taps
    start at zero). Decoders: block path (``linear_context`` 0) -- the PCA reconstruction for the upper body
    (the autoencoder then reconstructs exactly like the PCA) and the least-squares map from the codes for the
    lower body; lapped path -- the least-squares maps of :func:`lapped_decoder_fit` from latent frames
    t - c .. t + c for both, with ``velocity_weight`` on the frame-to-frame differences (for the upper body;
    the lower body is fitted on frames only when it is 0).

    uppers / lowers: the training clips ``(F_i, 39)`` / ``(F_i, 24)``; with ``config.standardize`` the stored
    statistics in ``params`` are used to express the maps in standardised units (set them first).
    Not in the paper: the starting point of ``AutoencoderConfig.linear_path``.
    """
    if not config.linear_path:
        raise ValueError("init_linear_path needs AutoencoderConfig.linear_path=True")
    r, d, c = config.time_reduction, config.latent_dim, config.linear_context
    pca = baselines.block_pca_fit(uppers, components=d, frames=r)
    mu, v = pca["mean"], pca["basis"]  # (r*39,), (d, r*39): z = v (x - mu), x_hat = mu + v^T z
    ups = [np.asarray(u, np.float64)[:len(u) // r * r] for u in uppers]
    los = [np.asarray(l, np.float64)[:len(l) // r * r] for l in lowers]
    codes = [(u.reshape(-1, r * u.shape[1]) - mu) @ v.T for u in ups]

    def stats(part, ch):
        if config.standardize:
            return (np.tile(np.asarray(params[f"{part}_mean"], np.float64), r),
                    np.tile(np.asarray(params[f"{part}_std"], np.float64), r))
        return np.zeros(r * ch), np.ones(r * ch)

    m_up, s_up = stats("upper", config.upper_channels)
    m_lo, s_lo = stats("lower", config.lower_channels)
    # encoder on standardised x_s = (x - m) / s: z = (v * s) x_s + v (m - mu); conv kernel ((2c+1) r, 39, d),
    # the block itself in the middle taps
    k_enc = np.zeros(((2 * c + 1) * r, config.upper_channels, d))
    k_enc[c * r:(c + 1) * r] = (v * s_up).reshape(d, r, config.upper_channels).transpose(1, 2, 0)
    b_enc = v @ (m_up - mu)
    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    out = dict(params)
    out["linear_encoder"] = {"kernel": f32(k_enc), "bias": f32(b_enc)}

    def decoder(w, m, s):  # w: (features + 1, r*C) raw units -> standardised y = (x - m) / s
        kernel, bias = w[:-1] / s, (w[-1] - m) / s
        if c:  # conv kernel (2c+1, d, r*C) over latent frames t-c .. t+c
            kernel = kernel.reshape(2 * c + 1, d, -1)
        return {"kernel": f32(kernel), "bias": f32(bias)}

    def lapped(targets, ch, vw):  # (r, p, C) -> (p, r*C) with block frames outermost
        w = lapped_decoder_fit(codes, targets, frames=r, context=c, velocity_weight=vw)
        return w.transpose(1, 0, 2).reshape(w.shape[1], r * ch)

    if c:
        w_up = lapped(ups, config.upper_channels, velocity_weight)
        w_lo = lapped(los, config.lower_channels, velocity_weight)
    else:
        w_up = np.concatenate([v, mu[None]], axis=0)
        z = np.concatenate(codes)
        lo_blocks = np.concatenate([l.reshape(-1, r * l.shape[1]) for l in los])
        w_lo = np.linalg.lstsq(np.concatenate([z, np.ones((len(z), 1))], axis=1), lo_blocks, rcond=None)[0]
    out["linear_upper"] = decoder(w_up, m_up, s_up)
    out["linear_lower"] = decoder(w_lo, m_lo, s_lo)
    for stack in ("encoder", "upper_decoder", "lower_decoder"):
        last = max((k for k in params[stack]), key=lambda k: int(k.split("_")[1]))
        out[stack] = dict(params[stack], **{last: jax.tree_util.tree_map(jnp.zeros_like, params[stack][last])})
    return out


def expmap_reconstruction_loss(pred: jax.Array, target: jax.Array) -> jax.Array:
    """Mean over frames and joints of the per-joint exp-map difference norm ``||r_hat - r||_2``.

    pred, target: ``(batch, frames, 3J)``. Returns ``(batch,)``. The paper (§3.5) speaks of "the mean
    square of ... angular differences"; docs/design.md §3 follows the authors' code, which averages the plain
    (unsquared) L2 norm of exp-map differences, as done here.
    References: Kuriyama et al. 2022, §3.5 (authors' code ``AutoEncoder.loss_function``).
    """
    chex.assert_equal_shape([pred, target])
    b, f, c = pred.shape
    d = (pred - target).reshape(b, f, c // 3, 3)
    return jnp.mean(safe_norm(d), axis=(1, 2))


def expmap_velocity_loss(pred: jax.Array, target: jax.Array) -> jax.Array:
    """Mean over frame pairs and joints of ``||(r_hat[t+1] - r_hat[t]) - (r[t+1] - r[t])||_2``: the
    reconstruction error of the frame-to-frame change (jitter and frozen motion both cost). ``(batch,)``.

    Not in the paper: an optional recipe term (``AutoencoderTrainConfig.velocity_weight``).
    """
    chex.assert_equal_shape([pred, target])
    return expmap_reconstruction_loss(jnp.diff(pred, axis=1), jnp.diff(target, axis=1))


#: the trunk joints of ``train.autoencoder.trunk_weight`` (:func:`trunk_channels`)
TRUNK_JOINTS = ("Hips", "Spine", "Chest")


def upper_joint_channels(joints) -> np.ndarray:
    """Exp-map channels of the named joints in the upper-body layout (:data:`jaxgest.motion.body.UPPER`)."""
    return np.concatenate([np.arange(3 * i, 3 * i + 3) for i in (body.UPPER.index(j) for j in joints)])


def trunk_channels() -> np.ndarray:
    """Exp-map channels of :data:`TRUNK_JOINTS` in the upper-body layout."""
    return upper_joint_channels(TRUNK_JOINTS)


def mean_angular_error_deg(pred: jax.Array, target: jax.Array) -> jax.Array:
    """Mean over frames and joints of the geodesic rotation error in degrees; ``(batch, F, 3J) -> (batch,)``.

    References: Kuriyama et al. 2022, §3.5 (the authors' ``evaluation`` reports this angle).
    """
    return jnp.degrees(jnp.mean(angular_error_rad(pred, target), axis=(1, 2)))


def _body_positions_joint_major(upper: jax.Array, lower: jax.Array) -> jax.Array:
    """:func:`body_positions` as ``(21, ..., F, 3)`` (joints leading, the layout of
    :func:`jaxgest.motion.kinematics.fk_expmap_positions_joint_major`)."""
    sk = body.body_skeleton()
    order = np.array([body.BODY.index(n) for n in sk.names])
    ex = jnp.concatenate([upper, lower], axis=-1)
    ex = jnp.moveaxis(ex.reshape(ex.shape[:-1] + (len(body.BODY), 3)), -2, 0)[order]  # rows: cheap
    offsets = np.array(sk.offsets, np.float32)
    offsets[np.asarray(sk.parents) < 0] = 0.0  # the root at the origin
    return kinematics.fk_expmap_positions_joint_major(ex, offsets, tuple(int(p) for p in sk.parents))


def body_positions(upper: jax.Array, lower: jax.Array) -> jax.Array:
    """Joint positions ``(..., F, 21, 3)`` (cm) of the canonical body posed by body exp-maps.

    upper ``(..., F, 39)``, lower ``(..., F, 24)`` (:data:`jaxgest.motion.body.UPPER` then ``LOWER``
    joints, Hips yaw already removed, as :func:`jaxgest.motion.body.motion_to_body` writes them) on
    :func:`jaxgest.motion.body.body_skeleton`'s bones; the Hips at the origin with its (yaw-free) rotation
    kept, i.e. world positions up to the root's path and heading, which the content supplies at transfer.
    """
    return jnp.moveaxis(_body_positions_joint_major(upper, lower), 0, -2)


def position_velocity_errors(pred_upper: jax.Array, pred_lower: jax.Array, upper: jax.Array,
                             lower: jax.Array) -> jax.Array:
    """``||(p_hat[t+1] - p_hat[t]) - (p[t+1] - p[t])||_2`` (cm per frame) per frame pair and joint,
    ``(batch, F - 1, 21)`` in :func:`jaxgest.motion.body.body_skeleton` order, with ``p`` the
    :func:`body_positions` of the decoded and of the input exp-maps (computed joint-major, transposed once)."""
    chex.assert_equal_shape([pred_upper, upper])
    chex.assert_equal_shape([pred_lower, lower])
    dp = jnp.diff(_body_positions_joint_major(pred_upper, pred_lower), axis=-2)  # (21, ..., F - 1, 3)
    dt = jnp.diff(_body_positions_joint_major(upper, lower), axis=-2)
    return jnp.moveaxis(safe_norm(dp - dt), 0, -1)  # (21, ..., F - 1) -> (..., F - 1, 21)


def position_velocity_loss(errors: jax.Array, joints: str = "all") -> jax.Array:
    """Mean over frame pairs and joints of :func:`position_velocity_errors` ``(batch, F - 1, 21)``: the
    reconstruction error of every joint's frame-to-frame displacement (cm per frame). ``(batch,)``.
    ``joints``: ``"all"`` 21 joints, ``"upper"`` the 13 upper-body joints (the legs' displacements left out).

    Unlike :func:`expmap_velocity_loss` it weighs a joint's rotation by the lever arm it moves (a trunk
    joint moves everything above it). Not in the paper: an optional recipe term
    (``AutoencoderTrainConfig.position_velocity_weight`` and ``position_velocity_joints``).
    """
    if joints not in POSITION_VELOCITY_JOINTS:
        raise ValueError(f"joints must be one of {POSITION_VELOCITY_JOINTS}, got {joints!r}")
    if joints == "upper":
        names = body.body_skeleton().names
        errors = errors[..., np.array([names.index(n) for n in body.UPPER])]
    return jnp.mean(errors, axis=(1, 2))

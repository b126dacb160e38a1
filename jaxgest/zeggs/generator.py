"""ZeroEGGS gesture generator: hidden-state initializer, recurrent decoder, character-state update.

Per frame t >= 1 the recurrent decoder reads ``[y_{t-1} (normalised pose state), target facing in the
root frame, s_t (speech embedding), e (style)]``, applies a linear layer with ELU, feeds
``[that, input]`` to two stacked GRU layers and a linear output layer that predicts the normalised pose
y_t. The "Update Character State" block denormalises y_t and integrates the predicted root velocities
into the root transform (position + yaw quaternion); y_t is fed back (no teacher forcing). Frame 0 is the
given initial pose. As in the authors' code, the pose is predicted in the per-channel (output)
normalisation and read back in the input normalisation, one std per feature group (:func:`input_scale`). The hidden-state initializer (3 linear layers, ELU after the first two, as in the
authors' code) maps ``[y_0, facing in the root frame, e]`` to the hidden states of all GRU layers.

:class:`RecurrentDecoder` is one step (an ``nn.RNNCellBase`` whose carry is ``(hidden states, pose state,
root position, root rotation)``); :class:`Generator` runs it with ``nn.scan`` so one compiled loop covers
the sequence; :func:`generate_loop_reference` runs the same step in a Python loop (tests).

The GRU follows PyTorch's ``nn.GRU`` equations and parameter count (input and hidden biases for the three
gates). The target-facing input is the unit facing direction rotated into the current root frame, not
normalised (it is already O(1)); the authors normalise it with the other inputs.

The decoder's linear layers are :class:`Dense` (``nn.Dense``'s parameters and initialisers): their kernels
may be given in a narrow weight format at inference (:mod:`jaxgest.zeggs.quant`), so every format runs
this same recurrence.

References: Ghorbani et al. 2023, §3.3 (Fig. 4) and §4.2; Harvey & Pal 2018 (separate initializer);
Cho et al. 2014 (GRU).
"""

from __future__ import annotations

import functools
from typing import Any, Optional

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp

from jaxgest.motion import rotations
from jaxgest.zeggs.config import ModelConfig
from jaxgest.zeggs.quant import QuantKernel, dense_apply

Carry = tuple[tuple[jax.Array, ...], jax.Array, jax.Array, jax.Array]


class Dense(nn.Module):
    """``nn.Dense`` (same parameters ``kernel (in, out)``, ``bias (out,)`` and initialisers) whose kernel may
    also be a narrow :class:`jaxgest.zeggs.quant.QuantKernel` (weight formats, inference only): the product
    is :func:`jaxgest.zeggs.quant.dense_apply` in both cases."""

    features: int

    @nn.compact
    def __call__(self, x: jax.Array, record: Optional[dict] = None) -> jax.Array:
        """``x @ kernel + bias``; with ``record`` (a dict, :func:`decoder_hoisted` only) the layer also adds
        ``record["perturb"][name]`` to its output and stores its input in ``record["inputs"][name]``."""
        shape = (x.shape[-1], self.features)
        stored = self.get_variable("params", "kernel") if self.has_variable("params", "kernel") else None
        if isinstance(stored, QuantKernel):
            if stored.shape != shape:
                raise ValueError(f"{self.name}: quantised kernel of shape {stored.shape}, expected {shape}")
            kernel = stored
        else:
            kernel = self.param("kernel", nn.initializers.lecun_normal(), shape, jnp.float32)
        bias = self.param("bias", nn.initializers.zeros_init(), (self.features,), jnp.float32)
        if self.is_mutable_collection("calibration"):  # model.calibrate: the mean input of every layer
            self.sow("calibration", "input_mean", jnp.mean(x.reshape(-1, x.shape[-1]), axis=0))
        y = dense_apply(x, kernel, bias)
        if record is not None:
            key = "/".join(self.scope.path[-2:]) if self.name in ("input", "hidden") else self.name
            record["inputs"][key] = x
            y = y + record["perturb"][key]
        return y


class GRULayer(nn.Module):
    """One GRU step ``(h (batch, H), x (batch, I)) -> h'`` with PyTorch's gate layout (r, z, n).

    References: Cho et al. 2014; PyTorch ``nn.GRU`` (b_hn inside the reset product).
    """

    features: int

    @nn.compact
    def __call__(self, h: jax.Array, x: jax.Array, record: Optional[dict] = None) -> jax.Array:
        H = self.features
        gi = Dense(3 * H, name="input")(x, record)
        gh = Dense(3 * H, name="hidden")(h, record)
        r = nn.sigmoid(gi[:, :H] + gh[:, :H])
        z = nn.sigmoid(gi[:, H:2 * H] + gh[:, H:2 * H])
        n = jnp.tanh(gi[:, 2 * H:] + r * gh[:, 2 * H:])
        return (1.0 - z) * n + z * h


def update_character_state(pose: jax.Array, root_position: jax.Array, root_rotation: jax.Array, *,
                           cfg: ModelConfig, pose_mean: jax.Array, pose_std: jax.Array):
    """Integrate the root: denormalise the predicted root velocities and step the root transform.

    pose ``(batch, P)`` normalised prediction of frame t; root_position ``(batch, 3)``, root_rotation
    ``(batch, 4)`` of frame t-1. Returns the root position and (unit) rotation of frame t:
    ``q_t = exp(q_{t-1} w_t dt) q_{t-1}``, ``p_t = p_{t-1} + q_t v_t dt`` with ``v_t, w_t`` in the root
    frame -- the inverse of :func:`jaxgest.zeggs.features.extract_features` (same as ``integrate_root``).
    References: Ghorbani et al. 2023, §3.3 ("Update Character State").
    """
    lay = cfg.layout
    dt = 1.0 / cfg.fps
    vel = pose[:, lay.root_velocity] * pose_std[None, lay.root_velocity] + pose_mean[None, lay.root_velocity]
    ang = pose[:, lay.root_angular_velocity] * pose_std[None, lay.root_angular_velocity] \
        + pose_mean[None, lay.root_angular_velocity]
    turn = rotations.expmap_to_quat(rotations.quat_rotate(root_rotation, ang) * dt)
    rot = rotations.quat_normalize(rotations.quat_mul(turn, root_rotation))
    pos = root_position + rotations.quat_rotate(rot, vel) * dt
    return pos, rot


def input_scale(cfg: ModelConfig, pose_mean: jax.Array, pose_std: jax.Array) -> jax.Array:
    """Per-channel factor ``(P,)`` from the per-channel (output) normalisation to the input normalisation.

    Inputs (style clips, the generator's pose state) are normalised as the authors do: per-channel mean,
    one std per feature group (root-frame positions, rotations, velocities, angular velocities, root
    velocity, root angular velocity) -- the std of all the group's values, i.e.
    ``sqrt(mean_c std_c^2 + var_c mean_c)`` -- so a near-constant channel is not blown up by its own tiny
    std. Outputs stay per channel. ``x_in = x_out * std_c / std_group``; ones when ``cfg.input_norm`` is
    ``"channel"`` (the old behaviour). References: the authors' data_pipeline.py (``anim_input_std`` one
    value per group, ``anim_output_std`` per channel).
    """
    std = jnp.asarray(pose_std)
    if cfg.input_norm == "channel":
        return jnp.ones_like(std)
    if cfg.input_norm != "group":
        raise ValueError(f"input_norm must be 'group' or 'channel', got {cfg.input_norm!r}")
    mean = jnp.asarray(pose_mean, std.dtype)
    lay = cfg.layout
    parts = []
    for g in (lay.local_positions, lay.local_rotations, lay.local_velocities, lay.local_angular_velocities,
              lay.root_velocity, lay.root_angular_velocity):
        m, s = mean[g], std[g]
        group = jnp.sqrt(jnp.mean(jnp.square(s)) + jnp.var(m))
        parts.append(s / jnp.maximum(group, 1e-12))
    return jnp.concatenate(parts)


def local_facing(facing: jax.Array, root_rotation: jax.Array) -> jax.Array:
    """World target facing direction ``(batch, 3)`` expressed in the root frame (``q^-1 f``)."""
    return rotations.quat_rotate(rotations.quat_inv(root_rotation), facing)


class HiddenStateInitializer(nn.Module):
    """``[y_0, facing, e]`` -> hidden states of every GRU layer (tuple of ``(batch, H)``).

    References: Ghorbani et al. 2023, §3.3, §4.2 (3 linear layers with ELU, hidden size 1024).
    """

    cfg: ModelConfig

    @nn.compact
    def __call__(self, pose0: jax.Array, facing0: jax.Array, style: jax.Array) -> tuple[jax.Array, ...]:
        cfg = self.cfg
        x = jnp.concatenate([pose0, facing0, style], axis=-1)
        x = nn.elu(nn.Dense(cfg.init_hidden, name="layer0")(x))
        x = nn.elu(nn.Dense(cfg.init_hidden, name="layer1")(x))
        h = nn.Dense(cfg.gru_hidden * cfg.gru_layers, name="layer2")(x)
        return tuple(jnp.split(h, cfg.gru_layers, axis=-1))


class RecurrentDecoder(nn.RNNCellBase):
    """One generator step: ``(carry, (s_t, e_t), (facing, mean, std)) -> (carry', (y_t, p_t, q_t))``.

    carry = ``(hidden states (tuple of (batch, H)), y_{t-1} (batch, P) normalised, root position
    (batch, 3), root rotation (batch, 4))``.
    References: Ghorbani et al. 2023, §3.3 (Fig. 4).
    """

    cfg: ModelConfig
    record: bool = False  # inputs carry per-layer output perturbations, outputs every layer's input (decoder_hoisted)

    @nn.compact
    def __call__(self, carry: Carry, inputs: tuple, consts: tuple[jax.Array, ...]):
        cfg = self.cfg
        hidden, pose, root_pos, root_rot = carry
        speech_t, style_t = inputs[:2]
        rec = {"perturb": inputs[2], "inputs": {}} if self.record else None
        facing, pose_mean, pose_std, in_scale = consts
        x = jnp.concatenate([pose * in_scale[None], local_facing(facing, root_rot), speech_t, style_t], axis=-1)
        h = nn.elu(Dense(cfg.gru_hidden, name="input_layer")(x, rec))
        h = jnp.concatenate([h, x], axis=-1)
        new_hidden = []
        for i in range(cfg.gru_layers):
            h = GRULayer(cfg.gru_hidden, name=f"gru{i}")(hidden[i], h, rec)
            new_hidden.append(h)
        y = Dense(cfg.pose_dim, name="output_layer")(h, rec)
        pos, rot = update_character_state(y, root_pos, root_rot, cfg=cfg, pose_mean=pose_mean, pose_std=pose_std)
        out = (y, pos, rot) + ((rec["inputs"],) if self.record else ())
        return (tuple(new_hidden), y, pos, rot), out

    @nn.nowrap
    def initialize_carry(self, rng, input_shape):  # the hidden-state initializer provides the carry
        raise NotImplementedError("use HiddenStateInitializer: the carry depends on pose, facing and style")

    @property
    def num_feature_axes(self) -> int:
        return 1


def _scanned_decoder(cfg: ModelConfig, record: bool = False, name: Optional[str] = None, parent=None):
    """:class:`RecurrentDecoder` under ``nn.scan`` over axis 1 (``parent=None``: a free module to ``apply``)."""
    scan = nn.scan(RecurrentDecoder, variable_broadcast="params", variable_axes={"calibration": 0},
                   split_rngs={"params": False}, in_axes=(1, nn.broadcast), out_axes=1)
    return scan(cfg, record, name=name) if name else scan(cfg, record, parent=parent)


def decoder_layers(cfg: ModelConfig) -> dict[str, int]:
    """The recurrent decoder's dense layers (``params["decoder"]`` paths joined by ``/``) and their widths."""
    layers = {"input_layer": cfg.gru_hidden}
    for i in range(cfg.gru_layers):
        layers[f"gru{i}/input"] = layers[f"gru{i}/hidden"] = 3 * cfg.gru_hidden
    layers["output_layer"] = cfg.pose_dim
    return layers


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def decoder_hoisted(cfg: ModelConfig, params, carry: Carry, inputs, consts):
    """The scanned decoder's outputs ``(ys, ps, qs)`` (as :class:`Generator`'s scan) with its weight gradients
    taken out of the backward loop.

    Reverse-mode through ``nn.scan`` accumulates every layer's weight gradient inside the backward loop:
    per frame and layer one ``(in, batch) x (batch, out)`` product, a third of the ``small`` generator's
    backward time. Here the backward loop runs with the weights as constants and returns each layer's
    output cotangent ``dY_t`` (the gradient of a zero perturbation added to the layer's output); after the
    loop, each layer's weight gradient is one product over all frames, ``dW = sum_t X_t^T dY_t``
    (``X_t`` the layer's inputs, recorded by the forward loop), ``db = sum_t dY_t``. Same values as the
    rolled gradient up to float summation order. Float kernels only (training); the primal (no gradient)
    is the plain scan. References: the chain rule for ``Y = X W + b``; Ghorbani et al. 2023, §3.3.
    """
    return _scanned_decoder(cfg).apply({"params": params}, carry, inputs, consts)[1]


def _hoisted_fwd(cfg, params, carry, inputs, consts):
    b, t = inputs[0].shape[:2]
    zeros = {k: jnp.zeros((b, t, n), inputs[0].dtype) for k, n in decoder_layers(cfg).items()}

    def run(carry, inputs, consts, perturb):
        y, p, q, rec = _scanned_decoder(cfg, record=True).apply({"params": params}, carry, inputs + (perturb,),
                                                                 consts)[1]
        return (y, p, q), rec

    out, vjp, rec = jax.vjp(run, carry, inputs, consts, zeros, has_aux=True)
    return out, (vjp, rec, params)


def _hoisted_bwd(cfg, res, g):
    vjp, rec, params = res
    d_carry, d_inputs, d_consts, d_out = vjp(g)
    grads = {}
    for key in decoder_layers(cfg):
        x, dy = rec[key], d_out[key]
        layer = {"kernel": jnp.einsum("bti,bto->io", x, dy), "bias": jnp.sum(dy, axis=(0, 1))}
        parts = key.split("/")
        (grads.setdefault(parts[0], {}) if len(parts) == 2 else grads)[parts[-1]] = layer
    grads = jax.tree_util.tree_map(lambda g_, p: g_.astype(p.dtype), grads, params)
    return grads, d_carry, d_inputs, d_consts


decoder_hoisted.defvjp(_hoisted_fwd, _hoisted_bwd)


def _float_params(tree) -> bool:
    return all(not isinstance(leaf, QuantKernel)
               for leaf in jax.tree_util.tree_leaves(tree, is_leaf=lambda x: isinstance(x, QuantKernel)))


def _prepare(cfg: ModelConfig, pose0, root_position0, root_rotation0, facing, speech, style, pose_mean, pose_std):
    b, T, _ = speech.shape
    chex.assert_shape(pose0, (b, cfg.pose_dim))
    chex.assert_shape(speech, (b, T, cfg.speech_embedding))
    chex.assert_shape([root_position0, facing], (b, 3))
    chex.assert_shape(root_rotation0, (b, 4))
    if style.ndim == 2:
        style = jnp.broadcast_to(style[:, None], (b, T, style.shape[-1]))
    chex.assert_shape(style, (b, T, cfg.style_embedding))
    dtype = pose0.dtype
    mean = jnp.zeros((cfg.pose_dim,), dtype) if pose_mean is None else jnp.asarray(pose_mean, dtype)
    std = jnp.ones((cfg.pose_dim,), dtype) if pose_std is None else jnp.asarray(pose_std, dtype)
    return style, (facing, mean, std, input_scale(cfg, mean, std))


def _stack_outputs(pose0, root_position0, root_rotation0, ys, ps, qs):
    return {
        "pose": jnp.concatenate([pose0[:, None], ys], axis=1),
        "root_position": jnp.concatenate([root_position0[:, None], ps], axis=1),
        "root_rotation": jnp.concatenate([root_rotation0[:, None], qs], axis=1),
    }


class Generator(nn.Module):
    """Autoregressive generator over a whole sequence (one ``nn.scan``).

    Inputs (batch b, frames T): ``pose0 (b, P)`` normalised initial pose, ``root_position0 (b, 3)``,
    ``root_rotation0 (b, 4)``, ``facing (b, 3)`` world target facing, ``speech (b, T, D_S)`` speech
    embeddings, ``style (b, D_e)`` or ``(b, T, D_e)`` style embeddings, ``pose_mean``/``pose_std (P,)``
    normalisation of the pose (default identity). Returns ``{"pose": (b, T, P) normalised, frame 0 =
    pose0, "root_position": (b, T, 3), "root_rotation": (b, T, 4)}``.
    References: Ghorbani et al. 2023, §3.3.
    """

    cfg: ModelConfig
    hoist_weight_grads: bool = True  # gradients through decoder_hoisted (same values); False: the plain scan

    def setup(self):
        self.initializer = HiddenStateInitializer(self.cfg, name="initializer")
        self.decoder = _scanned_decoder(self.cfg, name="decoder")

    def initial_carry(self, pose0, root_position0, root_rotation0, facing, style_seq, in_scale=None) -> Carry:
        hidden = self.initializer(pose0 if in_scale is None else pose0 * in_scale[None], local_facing(facing, root_rotation0), style_seq[:, 0])
        return hidden, pose0, root_position0, root_rotation0

    def __call__(self, pose0: jax.Array, root_position0: jax.Array, root_rotation0: jax.Array,
                 facing: jax.Array, speech: jax.Array, style: jax.Array,
                 pose_mean: Optional[jax.Array] = None, pose_std: Optional[jax.Array] = None) -> dict[str, Any]:
        style, consts = _prepare(self.cfg, pose0, root_position0, root_rotation0, facing, speech, style,
                                 pose_mean, pose_std)
        carry = self.initial_carry(pose0, root_position0, root_rotation0, facing, style, consts[3])
        inputs = (speech[:, 1:], style[:, 1:])
        params = self.variables.get("params", {}).get("decoder")
        if (self.hoist_weight_grads and params is not None and not self.is_initializing()
                and not self.is_mutable_collection("calibration") and _float_params(params)):
            ys, ps, qs = decoder_hoisted(self.cfg, params, carry, inputs, consts)
        else:
            _, (ys, ps, qs) = self.decoder(carry, inputs, consts)
        out = _stack_outputs(pose0, root_position0, root_rotation0, ys, ps, qs)
        chex.assert_shape(out["pose"], speech.shape[:2] + (self.cfg.pose_dim,))
        return out


def generate_loop_reference(cfg: ModelConfig, params, pose0, root_position0, root_rotation0, facing, speech,
                            style, pose_mean=None, pose_std=None) -> dict[str, Any]:
    """The generator as a slow Python loop over frames with the same ``params`` (tests only)."""
    style, consts = _prepare(cfg, pose0, root_position0, root_rotation0, facing, speech, style,
                             pose_mean, pose_std)
    hidden = HiddenStateInitializer(cfg).apply({"params": params["initializer"]}, pose0 * consts[3][None],
                                               local_facing(facing, root_rotation0), style[:, 0])
    carry: Carry = (hidden, pose0, root_position0, root_rotation0)
    cell = RecurrentDecoder(cfg)
    ys, ps, qs = [], [], []
    for t in range(1, speech.shape[1]):
        carry, (y, p, q) = cell.apply({"params": params["decoder"]}, carry, (speech[:, t], style[:, t]), consts)
        ys.append(y)
        ps.append(p)
        qs.append(q)
    return _stack_outputs(pose0, root_position0, root_rotation0, jnp.stack(ys, 1), jnp.stack(ps, 1),
                          jnp.stack(qs, 1))

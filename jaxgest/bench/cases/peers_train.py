"""Training steps side by side with PyTorch (``pip install ".[bench]"``): jit vs eager vs ``torch.compile``.

* ``peer_train_tgst_autoencoder``: the ``paper`` preset's autoencoder step (Adam, batch 32 x 256 frames);
* ``peer_train_tgst_transformer``: the style-transformer step (all four losses of eq. 12, Adam, batch 8
  content/style pairs of 1280 frames, autoencoder frozen) with the authors' transformer
  (``variant="authors"``, one LayerNorm per block: the network the peer ports), as the inference peers.

Implementations: ``jit`` (:func:`jaxgest.tgst.steps.make_ae_train_step` /
:func:`~jaxgest.tgst.steps.make_transformer_train_step`), ``torch`` / ``torch_1t`` (eager, every core /
one thread) and ``torch_compile`` (:mod:`jaxgest.bench.torch_peers.tgst_train`, ``compiled=True``), all from
the same initial weights (``init_params`` seed 0) on the same random batch. Every call is one whole
optimiser step and returns the step's observables (:func:`step_observables`): the loss and its terms,
the gradient norm and the update norm, checked equal (rtol ``RTOL``) on the first step before any timing.
The JAX step is called on the same input state each time (no donation); a PyTorch peer updates its own
weights in place, call after call (the cost of a step does not depend on the weights).

* ``peer_train_zeggs_small`` / ``peer_train_zeggs_paper`` (the latter not in ``--quick``): one RAdam step
  of :func:`jaxgest.zeggs.steps.make_train_step` at the preset's batch, window and longest style clip
  (:func:`jaxgest.bench.cases.training.zeggs_batch`: half the style clips shorter, masked), against
  :class:`jaxgest.bench.torch_peers.zeggs_train.ZeggsStepPeer` (speech and style encoders, the official
  generator loop, eq. 1-2 losses, KL, ``torch.optim.RAdam``). The benchmark config
  (:func:`zeggs_config`) is the preset with every dropout rate 0 (JAX's dropout masks cannot be reproduced
  in torch; dropout is a few elementwise ops) and a synthetic rig (:func:`bench_rig`: FK position terms on,
  as a training run on data); ``small``'s initial-pose shuffle is kept (ported). The style-sample noise and
  the shuffled rows are the JAX step's own draws (:func:`step_draws`, the step's key derivation), given to
  the peer. Parameters: ``init_params`` with small random biases (:func:`_zeggs_params`), so a mis-laid
  bias shows. Observables: as above plus ``recon``, ``kl``, ``kl_weight`` and every reconstruction term;
  tolerance ``ZEGGS_RTOL`` / ``ZEGGS_ATOL`` (float32 through a T-frame recurrence; on ``tiny`` the peer
  agrees to ~1e-7 relative; a 1.5x ``w_local_position`` moves the loss by ~1.4 %).

Work of a call: XLA's cost analysis of the jit step (no loops in the TGST steps, so the count is complete),
the same count for the peers; bytes = arguments + outputs of the JAX step. The ZeroEGGS generator is an
``nn.scan``: XLA counts a while loop's body once, so the cases add ``T - 2`` more bodies
(``Case.uncounted_flops``; one body forward and backward = XLA's count of ``jax.vjp`` of
:class:`jaxgest.zeggs.generator.RecurrentDecoder` at the batch, :func:`decoder_step_flops`) -- an estimate
(the backward loop's residual bookkeeping is counted as in that one vjp).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax.training.train_state import TrainState

from jaxgest.bench.cases import peers as PC
from jaxgest.bench.harness import Case, Impl
from jaxgest.tgst import model as TM
from jaxgest.tgst import steps as TS
from jaxgest.tgst.config import preset as tgst_config
from jaxgest.zeggs.config import preset as zeggs_config_of

BETA1 = 0.9
RTOL, ATOL = 2e-3, 1e-6  # float32 forward + backward through ~30 ops; a wrong loss weight moves the loss by %
# ZeroEGGS: float32 through a recurrent loop of T frames (errors grow along it) and 18 loss terms
ZEGGS_RTOL, ZEGGS_ATOL = 2e-3, 1e-5


def step_observables(step, keys):
    """The JAX step as the peers see it: ``(state, batch, key, *extra) -> {keys..., grad_norm, update_norm}``.

    ``grad_norm`` = ``||mu_1|| / (1 - beta1)`` (Adam's first moment after the first step), ``update_norm`` =
    the global L2 norm of the parameter change; the new state is otherwise discarded (all of it is needed
    for these two, so nothing of the step is optimised away).
    """

    def f(state, batch, key, *extra):
        new, metrics = step(state, batch, key, *extra)
        out = {k: metrics[k] for k in keys}
        out["grad_norm"] = optax.tree.norm(new.opt_state[0].mu) / (1.0 - BETA1)
        out["update_norm"] = optax.tree.norm(jax.tree_util.tree_map(jnp.subtract, new.params, state.params))
        return out

    return f


def config(preset: str = "paper"):
    """The preset with the authors' transformer (the network of the PyTorch peer)."""
    cfg = tgst_config(preset)
    t = cfg.model.transformer
    model = dataclasses.replace(cfg.model, transformer=dataclasses.replace(t, variant="authors",
                                                                          layernorms_per_block=1))
    return dataclasses.replace(cfg, model=model)


@functools.lru_cache(maxsize=None)
def _params(preset: str = "paper", seed: int = 0):
    cfg = config(preset)
    return jax.jit(lambda k: TM.init_params(cfg.model, k))(jax.random.key(seed))


def _f32(rng, shape, scale=1.0):
    return jnp.asarray(rng.normal(scale=scale, size=shape), jnp.float32)


def torch_impls(build) -> list:
    """``torch`` / ``torch_1t`` (eager) and ``torch_compile`` impls; ``build(compiled) -> step peer`` is called
    at an impl's first call, after its threads are set (each impl trains its own copy of the weights)."""
    from jaxgest.bench import torch_peers as P
    from jaxgest.bench.torch_peers.tgst_train import step_call

    out = []
    for name, n, compiled in [(nm, k, False) for nm, k in PC.torch_threads()] + [("torch_compile", PC.threads(),
                                                                                  True)]:
        holder = {}

        def fn(*args, _n=n, _c=compiled, _h=holder):
            P.set_threads(_n)
            if "f" not in _h:
                _h["f"] = step_call(build(_c))
            return _h["f"](*args)

        out.append(Impl(name, fn, kind="compiled" if compiled else "plain",
                        reference="torch" if compiled else None))
    return out


def ae_case(preset: str = "paper", *, with_torch: bool = True, batch: int | None = None,
            window: int | None = None) -> Case:
    cfg = config(preset)
    t = cfg.train.autoencoder
    tx = optax.adam(t.learning_rate)
    b, f = batch or t.batch_size, window or t.window
    impls = [Impl("jit", jax.jit(step_observables(TS.make_ae_train_step(cfg, tx),
                                                  ("loss", "upper_loss", "lower_loss"))), kind="jit")]
    if with_torch:
        from jaxgest.bench.torch_peers.tgst_train import AutoencoderStepPeer

        impls += torch_impls(lambda compiled: AutoencoderStepPeer(cfg.model, _params(preset), t.learning_rate,
                                                                  compiled=compiled, train=t))

    def make_args():
        state = TS.create_ae_state(cfg, _params(preset)["autoencoder"], tx)
        rng = np.random.default_rng(1)
        a = cfg.model.autoencoder
        batch_ = {"upper": _f32(rng, (b, f, a.upper_channels), 0.4),
                  "lower": _f32(rng, (b, f, a.lower_channels), 0.4)}
        return state, batch_, jax.random.key(0)

    return Case(name=f"peer_train_tgst_autoencoder{'' if preset == 'paper' else '_' + preset}", batch=b, frames=f,
                impls=impls, make_args=make_args, rtol=RTOL, atol=ATOL, interleave=True, max_repeats_slow=3,
                note=f"TGST {preset} autoencoder, one Adam step, batch {b} x {f} frames; torch threads "
                     f"{PC.threads()} / 1; torch_compile: loss (fwd+bwd) and optimizer step compiled")


def transformer_case(preset: str = "paper", *, with_torch: bool = True, batch: int | None = None,
                     window: int | None = None, train=None) -> Case:
    """``train``: the eq. 12 weights of the PyTorch peer (default: the preset's; a test passes wrong ones)."""
    cfg = config(preset)
    t = cfg.train.transformer
    tx = optax.adam(t.learning_rate)
    b, f = batch or t.batch_size, window or t.window

    def step(state, batch_, key, ae_params):
        # ae_params as an argument (as jaxgest.tgst.trainer does), not closed-over constants
        return TS.make_transformer_train_step(cfg, tx, ae_params)(state, batch_, key)

    keys = ("loss", "identity", "cyclic", "structure", "appearance")
    impls = [Impl("jit", jax.jit(step_observables(step, keys)), kind="jit")]
    if with_torch:
        from jaxgest.bench.torch_peers.tgst_train import TransformerStepPeer

        impls += torch_impls(lambda compiled: TransformerStepPeer(cfg.model, _params(preset), t.learning_rate,
                                                                  train or t, compiled=compiled))

    def make_args():
        p = _params(preset)
        state = TS.create_transformer_state(cfg, p["transformer"], tx)
        rng = np.random.default_rng(2)
        c = cfg.model.autoencoder.upper_channels
        batch_ = {"content": _f32(rng, (b, f, c), 0.4), "style": _f32(rng, (b, f, c), 0.4)}
        return state, batch_, jax.random.key(0), p["autoencoder"]

    return Case(name=f"peer_train_tgst_transformer{'' if preset == 'paper' else '_' + preset}", batch=b,
                frames=f, impls=impls, make_args=make_args, rtol=RTOL, atol=ATOL, interleave=True,
                max_repeats_slow=3,
                note=f"TGST {preset} style transformer (authors' variant), one Adam step on eq. 12 (4 losses), "
                     f"batch {b} pairs of {f} frames; torch threads {PC.threads()} / 1; torch_compile: loss "
                     f"(fwd+bwd) and optimizer step compiled")


# ------------------------------------------------------------------------------------------------------
# ZeroEGGS
# ------------------------------------------------------------------------------------------------------
def bench_rig(num_joints: int, seed: int = 0) -> dict:
    """A synthetic rig (``ModelConfig`` FK fields): joint j > 0 hangs from joint (j - 1) // 2 (a binary tree),
    root and hips translated, rest offsets of 5-20 cm. A training run takes its rig from the data
    (:func:`jaxgest.zeggs.features.fk_fields`), so the position terms use FK as in ``jaxgest zeggs train``."""
    rng = np.random.default_rng(seed)
    parents = (-1,) + tuple((j - 1) // 2 for j in range(1, num_joints))
    offsets = rng.uniform(-1.0, 1.0, (num_joints, 3))
    offsets = offsets / np.linalg.norm(offsets, axis=1, keepdims=True) * rng.uniform(5.0, 20.0, (num_joints, 1))
    offsets[0] = 0.0
    return {"fk_parents": parents, "fk_offsets": tuple(float(x) for x in offsets.reshape(-1)),
            "fk_translated": (0, 1) if num_joints > 1 else (0,)}


def zeggs_config(preset: str = "small", *, rig: bool = True, **fields):
    """The preset without dropout (the peer cannot reproduce JAX's dropout masks; dropout is a few
    elementwise ops next to the convs, attention and the GRU loop) and, with ``rig``, with
    :func:`bench_rig` (FK position terms on, as a training run on data). Everything else is the preset's,
    including ``small``'s initial-pose shuffle (ported). ``fields``: further bare-name overrides (tests)."""
    cfg = zeggs_config_of(preset)
    fields = dict(speech_dropout=0.0, style_dropout=0.0, style_attention_dropout=0.0, **fields)
    if rig:
        fields.update(bench_rig(cfg.model.num_joints))
    return cfg.override(**fields)


def step_draws(cfg, key, step: int, batch: int) -> dict:
    """What the JAX step draws from its key (:func:`jaxgest.zeggs.steps.loss_terms` after
    ``make_update_step(fold_in_step=True)``): ``eps`` ``(B, D_e)`` of the style sample and ``swap`` ``(B,)``
    the rows started from a replaced pose. Mirrors that derivation; a drift shows as a failed check."""
    from jaxgest.zeggs.steps import initial_pose_swaps

    t = cfg.train
    key = jax.random.fold_in(key, jnp.asarray(step, jnp.int32))
    _, k_sample = jax.random.split(key)
    swap = initial_pose_swaps(jax.random.fold_in(key, 0x1_5E), t.initial_pose_shuffle, batch)
    if t.initial_pose_source == "row" and batch == 1:
        swap = jnp.zeros_like(swap)
    eps = jax.random.normal(k_sample, (batch, cfg.model.style_embedding), jnp.float32)
    return {"eps": np.asarray(eps), "swap": np.asarray(swap)}


def _zeggs_params(cfg, seed: int = 0):
    """``init_params`` with small random biases (init's are zero: a mis-laid bias would go unseen)."""
    from jaxgest.zeggs.model import init_params

    params = init_params(cfg.model, jax.random.key(seed))
    rng = np.random.default_rng(seed + 10)

    def fill(path, leaf):
        if "bias" in jax.tree_util.keystr(path[-1:]):
            return jnp.asarray(rng.normal(scale=0.1, size=leaf.shape), jnp.float32)
        return leaf

    return jax.tree_util.tree_map_with_path(fill, params)


def decoder_step_flops(cfg, batch: int) -> float:
    """XLA's count of one generator frame, forward and backward (``jax.vjp`` of the scan body,
    :class:`jaxgest.zeggs.generator.RecurrentDecoder`, at ``batch``)."""
    from jaxgest.bench.harness import xla_cost
    from jaxgest.zeggs.generator import RecurrentDecoder, input_scale
    from jaxgest.zeggs.model import param_shapes

    m = cfg.model
    B, H, P = batch, m.gru_hidden, m.pose_dim
    dec = param_shapes(m)["generator"]["decoder"]
    def z(*shape):
        return jnp.zeros(shape, jnp.float32)

    mean, std = z(P), jnp.ones((P,), jnp.float32)
    consts = (z(B, 3), mean, std, input_scale(m, mean, std))
    q = z(B, 4).at[:, 0].set(1.0)

    def f(p, carry, inputs):
        out, vjp = jax.vjp(lambda p_, c_, i_: RecurrentDecoder(m).apply({"params": p_}, c_, i_, consts),
                           p, carry, inputs)
        return vjp(out)

    carry = (tuple(z(B, H) for _ in range(m.gru_layers)), z(B, P), z(B, 3), q)
    inputs = (z(B, m.speech_embedding), z(B, m.style_embedding))
    p = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), dec)
    cost = xla_cost(jax.jit(f).lower(p, carry, inputs).compile())
    return cost["flops"] if cost else 0.0


ZEGGS_KEYS = ("loss", "recon", "kl", "kl_weight", "local_position", "world_position", "local_rotation",
              "world_rotation", "local_velocity", "world_velocity", "local_angular", "world_angular",
              "fd_local_position", "fd_world_position", "fd_local_rotation", "fd_world_rotation", "root_position",
              "root_rotation", "root_velocity", "root_angular", "facing", "predicted_position")


def zeggs_case(preset: str = "small", *, with_torch: bool = True, batch: int | None = None,
               window: int | None = None, style_frames: int | None = None, peer_cfg=None,
               quick: bool = True, fields: dict | None = None, stats: dict | None = None) -> Case:
    """One RAdam step of ZeroEGGS (:func:`zeggs_config` with ``fields``); ``peer_cfg``: the PyTorch peer's
    config (default the same; a test passes a wrong one); ``stats``: pose ``{"mean", "std"}`` (default
    identity, as the training-step cases)."""
    from jaxgest.bench.cases.training import zeggs_batch
    from jaxgest.zeggs import steps as ZS

    cfg = zeggs_config(preset, **(fields or {}))
    t = cfg.train
    b, f, s = batch or t.batch_size, window or t.window, style_frames or t.style_window_max
    stats = ZS.pose_stats(cfg.model, **(stats or {}))
    key = jax.random.key(0)
    jit_step = jax.jit(step_observables(ZS.make_train_step(cfg), ZEGGS_KEYS),
                       compiler_options=t.compiler_options)
    impls = [Impl("jit", jit_step, kind="jit")]
    if with_torch:
        from jaxgest.bench.torch_peers.zeggs_train import ZeggsStepPeer

        impls += torch_impls(lambda compiled: ZeggsStepPeer(peer_cfg or cfg, _zeggs_params(cfg), stats,
                                                            step_draws(cfg, key, 0, b), compiled=compiled))

    def make_args():
        state = TrainState.create(apply_fn=None, params=_zeggs_params(cfg), tx=ZS.make_optimizer(cfg))
        return state, zeggs_batch(cfg.model, b, f, s), key, stats

    return Case(name=f"peer_train_zeggs_{preset}", batch=b, frames=f, impls=impls, make_args=make_args,
                rtol=ZEGGS_RTOL, atol=ZEGGS_ATOL, interleave=True, max_repeats_slow=3, quick=quick,
                uncounted_flops=lambda: (f - 2) * decoder_step_flops(cfg, b),
                note=f"ZEGGS {preset} preset without dropout, synthetic rig (FK terms), one RAdam step, batch {b} "
                     f"x {f} frames, style clips of {s} frames; torch threads {PC.threads()} / 1; torch_compile: "
                     f"encoders, per-frame generator step, losses (fwd+bwd) and optimizer step compiled, frame "
                     f"loop eager; flops = XLA's count + {f - 2} more scan bodies (fwd+bwd)")


def cases(quick: bool) -> list:
    with_torch = PC.torch_available()
    return [ae_case(with_torch=with_torch), transformer_case(with_torch=with_torch),
            zeggs_case("small", with_torch=with_torch), zeggs_case("paper", with_torch=with_torch, quick=False)]

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

Work of a call: XLA's cost analysis of the jit step (no loops in these steps, so the count is complete),
the same count for the peers; bytes = arguments + outputs of the JAX step.

ZeroEGGS training-step peers (``small`` / ``paper``) are not ported yet: the style encoder, speech
encoder, dropout, the reconstruction terms and RAdam would all need a PyTorch port first.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxgest.bench.cases import peers as PC
from jaxgest.bench.harness import Case, Impl
from jaxgest.tgst import model as TM
from jaxgest.tgst import steps as TS
from jaxgest.tgst.config import preset as tgst_config

BETA1 = 0.9
RTOL, ATOL = 2e-3, 1e-6  # float32 forward + backward through ~30 ops; a wrong loss weight moves the loss by %


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


def cases(quick: bool) -> list:
    with_torch = PC.torch_available()
    return [ae_case(with_torch=with_torch), transformer_case(with_torch=with_torch)]

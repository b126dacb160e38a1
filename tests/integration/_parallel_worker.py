"""Subprocess worker of tests/integration/test_parallel.py: train registered models data-parallel on N devices.

tests/integration/test_parallel.py calls ``main(["--devices", N, ...])`` in its own process (4 fake CPU devices, set by
tests/conftest.py) and runs it as a subprocess for the multi-process case:
``python tests/integration/_parallel_worker.py --devices N --steps K --batch B --seed S --out DIR [--model M ...]`` in a
process whose ``XLA_FLAGS`` holds ``--xla_force_host_platform_device_count=N`` (set by the parent before this
interpreter imports jax; ``--host-devices`` sets it here otherwise). For every model it runs
``K`` steps of :func:`jaxgest.runtime.training.train_loop` through :mod:`jaxgest.runtime.parallel` and writes

* ``DIR/<model>.npz``: the final parameters, keyed by their pytree path (``<model>_init.npz``: initial);
* ``DIR/<model>/metrics.jsonl``: the MetricsLogger output with the device info as extra fields;
* ``DIR/info.json``: per model the losses, how the first batch and the final parameters are laid out over
  the devices, whether the compiled step all-reduces, and the errors of bad device/batch requests.

Registry. ``BUILDERS`` maps a model name to ``builder(seed, batch_size) -> (state, step_fn, batch_fn)``:
``state`` a fresh ``TrainState`` built from ``seed`` alone, ``step_fn`` the *un-jitted*
``(state, batch, key) -> (state, metrics)`` with a ``loss`` metric that averages over the batch, and
``batch_fn(i)`` the host-global numpy batch pytree of step ``i`` (every leaf ``(batch_size, ...)``), a pure
function of ``(seed, i)``. Two toys are registered (an MLP and a strided conv net): the mechanism of
:mod:`jaxgest.runtime.parallel` does not depend on the model. The real models are checked through their ``train``
entry points instead (tests/integration/test_parallel.py, against the session's 1-device tiny models). Register another
builder with ``@register("name")``; the test picks every registered name up through ``--list``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys

if __name__ == "__main__" and "--host-devices" in sys.argv:  # before jax is imported
    _flag = "--xla_force_host_platform_device_count=" + sys.argv[sys.argv.index("--host-devices") + 1]
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_flag}"

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

BUILDERS: dict = {}


def register(name: str):
    """Decorator adding ``builder(seed, batch_size) -> (state, step_fn, batch_fn)`` to ``BUILDERS``."""

    def deco(fn):
        BUILDERS[name] = fn
        return fn

    return deco


def _regression_step(module):
    """Adam step on a mean squared error, with a key folded in (dropout-free models ignore it)."""

    def step(state, batch, key):
        del key

        def loss_fn(params):
            pred = module.apply({"params": params}, batch["x"])
            return jnp.mean((pred - batch["y"]) ** 2)

        loss, grads = jax.value_and_grad(loss_fn)(state.params)
        return state.apply_gradients(grads=grads), {"loss": loss, "grad_norm": _global_norm(grads)}

    return step


def _init_state(module, tx, seed: int, example):
    """TrainState from ``seed``, initialised inside one jit (eager flax init compiles every op apart)."""
    from jaxgest.runtime.training import TrainState

    def create(key):
        params = module.init(key, example)["params"]
        return TrainState.create(apply_fn=module.apply, params=params, tx=tx)

    return jax.jit(create)(jax.random.key(seed))


def _global_norm(tree):
    return jnp.sqrt(sum(jnp.sum(x**2) for x in jax.tree_util.tree_leaves(tree)))


@register("toy_mlp")
def build_toy_mlp(seed: int, batch_size: int):
    """2-layer GELU MLP regressing a fixed random nonlinear map, 8 -> 32 -> 4."""
    import flax.linen as nn
    import optax

    class MLP(nn.Module):
        @nn.compact
        def __call__(self, x):
            return nn.Dense(4)(nn.gelu(nn.Dense(32)(x)))

    module = MLP()
    state = _init_state(module, optax.adam(1e-2), seed, jnp.zeros((1, 8), jnp.float32))
    w = np.random.default_rng(seed + 1000).normal(size=(8, 4)).astype(np.float32)

    def batch_fn(i):
        rng = np.random.default_rng([seed, i])
        x = rng.normal(size=(batch_size, 8)).astype(np.float32)
        return {"x": x, "y": np.tanh(x @ w).astype(np.float32)}

    return state, _regression_step(module), batch_fn


@register("toy_conv1d")
def build_toy_conv1d(seed: int, batch_size: int):
    """Conv1d over time (B, 16 frames, 6 ch) -> (B, 16, 3), like the motion autoencoders in miniature."""
    import flax.linen as nn
    import optax

    class Conv(nn.Module):
        @nn.compact
        def __call__(self, x):
            h = nn.gelu(nn.Conv(12, (3,), strides=(2,))(x))
            h = jax.image.resize(h, (h.shape[0], x.shape[1], h.shape[2]), "linear")
            return nn.Conv(3, (3,))(h)

    module = Conv()
    state = _init_state(module, optax.adam(1e-2), seed, jnp.zeros((1, 16, 6), jnp.float32))

    def batch_fn(i):
        rng = np.random.default_rng([seed, i])
        x = np.cumsum(rng.normal(size=(batch_size, 16, 6)), axis=1).astype(np.float32) * 0.3
        y = np.stack([x[..., 0] * x[..., 1], np.sin(x[..., 2]), x[..., 3] - x[..., 5]], axis=-1)
        return {"x": x, "y": y.astype(np.float32)}

    return state, _regression_step(module), batch_fn


def _layout(arr) -> dict:
    """How a (global) array lies on the devices: spec, shard row ranges, whether each shard holds its rows."""
    shards = sorted(arr.addressable_shards, key=lambda s: s.device.id)
    return {
        "shape": list(arr.shape),
        "spec": str(arr.sharding.spec) if hasattr(arr.sharding, "spec") else None,
        "num_devices": len(arr.sharding.device_set),
        "num_shards": len(shards),
        "shard_shapes": [list(s.data.shape) for s in shards],
        "fully_replicated": bool(arr.sharding.is_fully_replicated),
        "row_starts": [s.index[0].start if arr.ndim and s.index[0].start is not None else 0 for s in shards],
    }


def _flat(tree) -> dict:
    return {jax.tree_util.keystr(p): np.asarray(jax.device_get(x)) for p, x in
            jax.tree_util.tree_flatten_with_path(tree)[0]}


def _error_of(fn):
    from jaxgest.runtime.errors import JaxgestError

    try:
        fn()
    except JaxgestError as e:
        return f"{type(e).__name__}: {e}"
    return None


def run_model(name: str, args, out: pathlib.Path) -> dict:
    from jaxgest.runtime import parallel
    from jaxgest.runtime.training import MetricsLogger, train_loop

    mesh = parallel.make_mesh(args.devices)
    state, step_fn, batch_fn = BUILDERS[name](args.seed, args.batch)
    np.savez(out / f"{name}_init.npz", **_flat(state.params))
    state = parallel.replicate(state, mesh)
    step = parallel.parallelize_step(step_fn, mesh)
    if args.host_local:  # each host reads only its block of the global batch
        def local_fn(i):
            return jax.tree_util.tree_map(parallel.host_shard, batch_fn(i))

        batches = parallel.sharded_batch_fn(local_fn, mesh, host_local=True)
    else:
        batches = parallel.sharded_batch_fn(batch_fn, mesh)
    info = parallel.device_info(mesh)

    first = batches(0)
    host_first = batch_fn(0)
    leaf = jax.tree_util.tree_leaves(first)[0]
    host_leaf = jax.tree_util.tree_leaves(host_first)[0]
    rows_match = all(np.array_equal(np.asarray(s.data), host_leaf[s.index]) for s in leaf.addressable_shards)
    if args.host_local:  # the other way of placing the same batch must give the same shards
        other = parallel.shard_batch(host_first, mesh)
    else:
        local = jax.tree_util.tree_map(parallel.host_shard, host_first)
        other = parallel.host_local_batch_to_global(local, mesh)
    paths_agree = all(
        a.index == b.index and np.array_equal(np.asarray(a.data), np.asarray(b.data))
        for x, y in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(other))
        for a, b in zip(sorted(x.addressable_shards, key=lambda s: s.device.id),
                        sorted(y.addressable_shards, key=lambda s: s.device.id)))
    key = jax.random.key(args.seed)
    # Compile once, ahead of time, and train with that executable (same program as calling ``step``).
    compiled = step.lower(state, first, key).compile()
    hlo = compiled.as_text()

    losses = []
    logger = MetricsLogger(out / name, extra=info)
    final = train_loop(state, compiled, batches, key=key, num_steps=args.steps, logger=logger, log_every=1,
                       progress=False, on_log=lambda i, m: losses.append(m["loss"]))
    params = _flat(final.params)
    np.savez(out / f"{name}.npz", **params)
    param_leaves = jax.tree_util.tree_leaves(final.params)
    return {
        "device_info": info,
        "losses": losses,
        "batch_layout": _layout(leaf),
        "batch_rows_match": bool(rows_match),
        "global_and_host_local_paths_agree": bool(paths_agree),
        "param_layouts": [_layout(x) for x in param_leaves],
        "step_layout": _layout(final.step),
        "all_reduce_in_hlo": "all-reduce" in hlo,
        "metrics_lines": (out / name / "metrics.jsonl").read_text().splitlines(),
    }


def error_checks(args) -> dict:
    """Messages of the errors a user can cause: too many / zero devices, a batch that does not divide."""
    from jaxgest.runtime import parallel

    mesh = parallel.make_mesh(args.devices)
    odd = {"x": np.zeros((mesh.size + 2, 3), np.float32)} if mesh.size > 1 else None
    return {
        "too_many": _error_of(lambda: parallel.make_mesh(jax.device_count() + 1)),
        "zero": _error_of(lambda: parallel.make_mesh(0)),
        "indivisible": _error_of(lambda: parallel.shard_batch(odd, mesh)) if odd is not None else None,
        "scalar": _error_of(lambda: parallel.shard_batch({"scale": np.float32(1.0)}, mesh)),
        "partial_mesh": _error_of(lambda: parallel.make_mesh(1)) if jax.process_count() > 1 else None,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--model", action="append", help="registered model (repeatable; default all)")
    p.add_argument("--devices", type=int, default=None)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=pathlib.Path)
    p.add_argument("--host-devices", type=int, help="fake CPU devices (sets XLA_FLAGS before importing jax)")
    p.add_argument("--host-local", action="store_true", help="each host builds only its block of the batch")
    p.add_argument("--list", action="store_true", help="print the registered model names and exit")
    args = p.parse_args(argv)
    if args.list:
        print(json.dumps(sorted(BUILDERS)))
        return 0
    from jaxgest.runtime import parallel
    from jaxgest.runtime.errors import JaxgestError

    try:
        parallel.maybe_initialize_distributed()  # multi-process when JAX_COORDINATOR_ADDRESS is set
        out = args.out if jax.process_count() == 1 else args.out / f"proc{jax.process_index()}"
        out.mkdir(parents=True, exist_ok=True)
        report = {"device_count": jax.device_count(), "local_device_count": jax.local_device_count(),
                  "process_index": jax.process_index(), "errors": error_checks(args), "models": {}}
        for name in args.model or sorted(BUILDERS):
            report["models"][name] = run_model(name, args, out)
    except JaxgestError as e:
        print(f"jaxgest: {e}", file=sys.stderr)
        return 2
    (out / "info.json").write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

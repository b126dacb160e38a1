"""Data-parallel training over every visible device: one ``jax.sharding.Mesh`` with a ``data`` axis.

The three models (TGST autoencoder, TGST transformer, ZEGGS) train with the same recipe; nothing here
knows about any of them. The batch is split along its leading axis over the ``data`` axis of the mesh and
the train state (parameters, optimizer state, step) is replicated on every device. The step is compiled
once with :func:`jax.jit` and explicit ``in_shardings``/``out_shardings`` (no ``pmap``); XLA inserts the
all-reduce, so ``jnp.mean`` over the batch inside the step *is* the mean over the global batch and the
same step function gives the same result on 1 or N devices (up to float reassociation of the sums).

Use from the model training code (``state`` a ``TrainState``, ``step_fn`` the *un-jitted*
``(state, batch, key) -> (state, metrics)``, ``batch_fn(i)`` a host-global numpy batch of step ``i``)::

    parallel.maybe_initialize_distributed()          # first thing, before any other JAX call
    mesh = parallel.make_mesh(args.devices)          # --devices N (None = all)
    state = parallel.replicate(state, mesh)          # before Checkpointer.restore (keeps the sharding)
    state = checkpointer.restore(state)
    step = parallel.parallelize_step(step_fn, mesh)  # jit, state donated
    batches = parallel.sharded_batch_fn(batch_fn, mesh)
    info = parallel.device_info(mesh)                # {"devices", "platform", "processes"}
    # write info into config.json and MetricsLogger(workdir, extra=info)
    state = train_loop(state, step, batches, key=key, num_steps=n)

Global batch. The batch size of a config is the GLOBAL batch: one optimizer step averages the loss over
that many examples whatever the number of devices, so a run on N devices follows the 1-device run. Each
device holds ``batch / N`` examples (the batch must be divisible by N, otherwise :func:`shard_batch` raises
a :class:`~jaxgest.runtime.errors.JaxgestError` naming the array). With several hosts, each host holds only
``batch / num_hosts`` examples on its devices. Two ways to feed it: (a) ``batch_fn`` returns the global
batch on every host (cheap for in-memory or generated data) and :func:`shard_batch` keeps this host's block;
(b) to *read* only its own share, ``batch_fn`` draws the global batch's example indices from ``(seed, i)``
exactly as on one host, keeps its contiguous block with :func:`host_shard`, loads only those, and
``sharded_batch_fn(batch_fn, mesh, host_local=True)`` assembles the global array
(:func:`host_local_batch_to_global`, ``jax.make_array_from_process_local_data``). Either way every host
trains on the same global batch as a single-host run, so the parameters do not depend on the number of
hosts. Only process 0 (``jax.process_index() == 0``) should write metrics.jsonl/config.json; every process
must call ``Checkpointer.save`` (orbax coordinates the hosts).

Several hosts. Start the same command on every host with, for example::

    JAX_COORDINATOR_ADDRESS=host0:1234 JAX_NUM_PROCESSES=2 JAX_PROCESS_ID=0 jaxgest train ...   # host 0
    JAX_COORDINATOR_ADDRESS=host0:1234 JAX_NUM_PROCESSES=2 JAX_PROCESS_ID=1 jaxgest train ...   # host 1

:func:`maybe_initialize_distributed` then calls :func:`jax.distributed.initialize`. The variables read:

* ``JAX_COORDINATOR_ADDRESS`` (``host:port`` of process 0) -- when set, the run is multi-process;
  ``JAX_NUM_PROCESSES`` and ``JAX_PROCESS_ID`` (integers) give the process count and this process' index;
  if either is absent it is left to JAX's cluster auto-detection (SLURM, Open MPI, Kubernetes, Cloud TPU).
* ``JAXGEST_DISTRIBUTED=1`` -- initialize even without ``JAX_COORDINATOR_ADDRESS`` and let JAX detect
  everything from the cluster environment (e.g. inside ``srun`` on SLURM, ``mpirun`` on Open MPI). A SLURM
  or MPI environment alone does not start the distributed runtime: single-task jobs stay single-process.

The mesh then holds every device of every host (``--devices`` must be omitted or equal to the global
count), ordered by process so host ``p`` owns the ``p``-th contiguous block of the global batch.
Checkpoints are written by orbax from all hosts into a shared ``--workdir``.

References: JAX "Distributed arrays and automatic parallelization" and "Multi-process" guides.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Optional

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxgest.runtime.errors import JaxgestError

__all__ = [
    "DATA_AXIS",
    "COORDINATOR_ENV",
    "maybe_initialize_distributed",
    "make_mesh",
    "data_sharding",
    "replicated",
    "shard_batch",
    "host_local_batch_to_global",
    "host_shard",
    "sharded_batch_fn",
    "replicate",
    "parallelize_step",
    "device_info",
]

DATA_AXIS = "data"
#: Environment variables read by :func:`maybe_initialize_distributed` (see the module docstring).
COORDINATOR_ENV = ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID", "JAXGEST_DISTRIBUTED")


def _env_int(env, name: str) -> Optional[int]:
    raw = env.get(name)
    if raw is None or raw.strip() == "":
        return None
    try:
        return int(raw)
    except ValueError:
        raise JaxgestError(f"environment variable {name}={raw!r} is not an integer") from None


def maybe_initialize_distributed(env=None) -> bool:
    """Start JAX's multi-process runtime when the coordinator environment asks for it; idempotent.

    Calls :func:`jax.distributed.initialize` when ``JAX_COORDINATOR_ADDRESS`` is set (with
    ``JAX_NUM_PROCESSES`` / ``JAX_PROCESS_ID`` when given) or when ``JAXGEST_DISTRIBUTED=1`` (cluster
    auto-detection by JAX). Must run before any other JAX computation. Returns True when the distributed
    runtime is initialized (now or by an earlier call), False for an ordinary single-process run.

    Args:
      env: mapping read instead of ``os.environ`` (tests).
    """
    env = os.environ if env is None else env
    if jax.distributed.is_initialized():
        return True
    address = env.get("JAX_COORDINATOR_ADDRESS") or None
    forced = env.get("JAXGEST_DISTRIBUTED", "").strip().lower() in ("1", "true", "yes")
    if address is None and not forced:
        return False
    num_processes = _env_int(env, "JAX_NUM_PROCESSES")
    process_id = _env_int(env, "JAX_PROCESS_ID")
    if num_processes is not None and num_processes < 1:
        raise JaxgestError(f"JAX_NUM_PROCESSES={num_processes} must be at least 1")
    if process_id is not None and num_processes is not None and not 0 <= process_id < num_processes:
        raise JaxgestError(f"JAX_PROCESS_ID={process_id} must be in [0, JAX_NUM_PROCESSES={num_processes})")
    try:
        jax.distributed.initialize(coordinator_address=address, num_processes=num_processes,
                                   process_id=process_id)
    except (RuntimeError, ValueError) as e:
        first = str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__
        raise JaxgestError(f"cannot start the multi-host runtime ({first}); check JAX_COORDINATOR_ADDRESS, "
                           "JAX_NUM_PROCESSES and JAX_PROCESS_ID") from None
    return True


def make_mesh(num_devices: Optional[int] = None) -> Mesh:
    """1-D mesh with axis ``"data"`` over the first ``num_devices`` devices (all when None).

    In a multi-process run the mesh holds every global device (``num_devices`` must be None or the global
    count), ordered by process index so each process' devices hold one contiguous block of the batch.
    """
    devices = jax.devices()
    available = len(devices)
    multi = jax.process_count() > 1
    if num_devices is None:
        num_devices = available
    if isinstance(num_devices, bool) or not isinstance(num_devices, (int, np.integer)):
        raise JaxgestError(f"--devices must be an integer, got {num_devices!r}")
    num_devices = int(num_devices)
    if num_devices < 1:
        raise JaxgestError(f"--devices {num_devices}: need at least 1 device")
    if num_devices > available:
        platform = devices[0].platform
        raise JaxgestError(f"--devices {num_devices}: only {available} {platform} device(s) available")
    if multi and num_devices != available:
        raise JaxgestError(f"--devices {num_devices}: a {jax.process_count()}-process run uses all "
                           f"{available} devices; omit --devices")
    if multi:
        devices = sorted(devices, key=lambda d: (d.process_index, d.id))
    return Mesh(np.asarray(devices[:num_devices]), (DATA_AXIS,))


def data_sharding(mesh: Mesh) -> NamedSharding:
    """Leading (batch) axis split over ``"data"``, the other axes whole."""
    return NamedSharding(mesh, PartitionSpec(DATA_AXIS))


def replicated(mesh: Mesh) -> NamedSharding:
    """A full copy on every device of the mesh."""
    return NamedSharding(mesh, PartitionSpec())


def _check_divisible(batch, parts: int, what: str) -> None:
    for path, leaf in jax.tree_util.tree_flatten_with_path(batch)[0]:
        name = jax.tree_util.keystr(path) or "<batch>"
        shape = np.shape(leaf)
        if len(shape) == 0:
            raise JaxgestError(f"batch array {name} is a scalar; every batch array needs a leading batch "
                               "axis")
        if shape[0] % parts:
            divisors = ", ".join(str(d) for d in range(1, shape[0] + 1) if shape[0] % d == 0)
            raise JaxgestError(f"batch array {name} has {shape[0]} examples, not divisible by the {parts} "
                               f"{what}; use a device count that divides the global batch ({divisors}) or "
                               f"a batch size that is a multiple of {parts}")


def shard_batch(batch: Any, mesh: Mesh) -> Any:
    """Place the GLOBAL batch pytree on the mesh with its leading axis split over ``"data"``.

    Every leaf is ``(batch, ...)``; device ``k`` of ``N`` gets rows ``[k*batch/N, (k+1)*batch/N)``. With
    several processes every host passes the same global batch and keeps only its own block
    (:func:`host_shard`, then :func:`host_local_batch_to_global`); a pipeline that loads only its block
    calls :func:`host_local_batch_to_global` directly.
    Raises JaxgestError naming the array when its leading size does not divide over the devices.
    """
    _check_divisible(batch, mesh.size, "devices")
    if jax.process_count() > 1:
        return host_local_batch_to_global(jax.tree_util.tree_map(host_shard, batch), mesh)
    return jax.device_put(batch, data_sharding(mesh))


def host_local_batch_to_global(local_batch: Any, mesh: Mesh) -> Any:
    """Global data-sharded arrays from each process' contiguous block of the batch.

    Each leaf ``(batch / num_processes, ...)`` becomes a global ``(batch, ...)`` array; process ``p``'s rows
    are rows ``[p*b, (p+1)*b)`` of it (the order of :func:`host_shard` and :func:`make_mesh`).
    """
    local_devices = sum(d.process_index == jax.process_index() for d in mesh.devices.flat)
    _check_divisible(local_batch, local_devices, "devices of this host")
    sharding = data_sharding(mesh)
    procs = jax.process_count()

    def to_global(x):
        x = np.asarray(x)
        return jax.make_array_from_process_local_data(sharding, x, (x.shape[0] * procs,) + x.shape[1:])

    return jax.tree_util.tree_map(to_global, local_batch)


def host_shard(x, process_index: Optional[int] = None, process_count: Optional[int] = None):
    """This host's contiguous block of ``x`` along axis 0 (all of it in a single-process run).

    Give it the example indices (or any array) of the GLOBAL batch, drawn identically on every host from
    ``(seed, step)``; host ``p`` of ``P`` keeps rows ``[p*n/P, (p+1)*n/P)`` and loads only those.

    Args:
      x: array-like with a leading axis of the global size ``n`` (divisible by ``process_count``).
      process_index / process_count: default ``jax.process_index()`` / ``jax.process_count()``.
    """
    process_index = jax.process_index() if process_index is None else int(process_index)
    process_count = jax.process_count() if process_count is None else int(process_count)
    if process_count < 1 or not 0 <= process_index < process_count:
        raise JaxgestError(f"host {process_index} of {process_count}: invalid process index/count")
    x = np.asarray(x)
    n = x.shape[0] if x.ndim else 0
    if x.ndim == 0 or n % process_count:
        raise JaxgestError(f"global batch of {n} examples does not divide over {process_count} hosts; "
                           f"choose a batch size that is a multiple of {process_count}")
    per = n // process_count
    return x[process_index * per:(process_index + 1) * per]


def sharded_batch_fn(batch_fn: Callable[[int], Any], mesh: Mesh, *,
                     host_local: bool = False) -> Callable[[int], Any]:
    """``i -> `` the batch of step ``i`` on the mesh, for :func:`jaxgest.runtime.training.train_loop`.

    ``batch_fn(i)`` returns the global batch (default; :func:`shard_batch`) or, with ``host_local=True``,
    only this host's block of it (:func:`host_local_batch_to_global`; same as the default on one host).
    """
    place = host_local_batch_to_global if host_local else shard_batch

    def fn(i: int):
        return place(batch_fn(i), mesh)

    return fn


def replicate(tree: Any, mesh: Mesh) -> Any:
    """Copy a pytree (e.g. a ``TrainState``; static fields untouched) to every device of the mesh."""
    sharding = replicated(mesh)
    if jax.process_count() == 1:
        return jax.device_put(tree, sharding)

    def put(x):
        host = np.asarray(jax.device_get(x))  # identical on every host (same seed / same checkpoint)
        return jax.make_array_from_callback(host.shape, sharding, lambda idx: host[idx])

    return jax.tree_util.tree_map(put, tree)


def parallelize_step(step_fn: Callable, mesh: Mesh, donate: bool = True, *, extra_args: int = 0,
                     compiler_options: Optional[dict] = None) -> Callable:
    """Compile ``step_fn(state, batch, key, *extra) -> (state, metrics)`` data-parallel over ``mesh``.

    ``jax.jit`` with the state, key and ``extra_args`` further arguments (e.g. dataset statistics)
    replicated, the batch split over ``"data"``, the new state and the metrics replicated, and the state
    donated (its buffers are reused; do not touch the old state); ``compiler_options`` go to ``jax.jit``.
    ``step_fn`` is the plain step: means over the batch inside it are global means (XLA adds the
    cross-device reduction), so it is written exactly as for one device.
    """
    rep, data = replicated(mesh), data_sharding(mesh)
    return jax.jit(step_fn, in_shardings=(rep, data, rep) + (rep,) * extra_args, out_shardings=(rep, rep),
                   donate_argnums=(0,) if donate else (), compiler_options=compiler_options)


def device_info(mesh: Mesh) -> dict:
    """``{"devices", "platform", "processes"}`` of a mesh, for config.json and metrics.jsonl."""
    first = mesh.devices.flat[0]
    return {"devices": int(mesh.size), "platform": str(first.platform), "processes": int(jax.process_count())}

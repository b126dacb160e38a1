"""Shared pieces of the fault tests (tests/test_faults_*.py): the one-line CLI runner, snapshots, checkpoint
corruptions, a toy training problem, and SIGKILL of a subprocess at a marker.

The CLI cases run ``jaxgest.cli.main`` in-process on the session's tiny trained workdirs (conftest ``tiny``:
TGST 4+4 steps, ZeroEGGS 4 steps, checkpoints every 2 steps, so each stage keeps steps 2 and 4), always on a
copy when the case changes the workdir.
"""

from __future__ import annotations

import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxgest import cli
from jaxgest.runtime.training import TrainState

REPO = pathlib.Path(__file__).resolve().parents[2]
NOISE = ("Traceback", "Event loop is closed", "absl", "WARNING:", "ERROR:")


def snapshot(folder: pathlib.Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def run(argv, capsys) -> tuple[int, str, str]:
    """``(status, the one stderr line, stdout)``; fails on more than one line or any traceback/noise."""
    capsys.readouterr()
    rc = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    for bad in NOISE:
        assert bad not in err, err
    assert err.count("\n") <= 1 and "\r" not in err, repr(err)
    return rc, err.rstrip("\n"), out


def copy(tiny, model, tmp_path) -> pathlib.Path:
    work = tmp_path / model
    shutil.copytree(tiny["tw" if model == "tgst" else "zw"], work)
    return work


def infer(tiny, model, work, out, strict=False) -> list:
    argv = (["tgst", "transfer", "--workdir", work, "--content", tiny["content"], "--style", tiny["style"]]
            if model == "tgst" else
            ["zeggs", "generate", "--workdir", work, "--audio", tiny["wav"], "--style", tiny["style"]])
    return argv + ["--out", out] + (["--strict"] if strict else [])


STAGE = {"tgst": "transformer", "zeggs": "zeggs"}


def _data_files(step_dir):
    return sorted((step_dir / "state").rglob("d/*"), key=lambda p: (-p.stat().st_size, p.name))


def truncate_data(step_dir):  # a crash during a copy, a full disk
    for f in _data_files(step_dir):
        os.truncate(f, min(100, f.stat().st_size // 2))


def _read_arrays(state_dir) -> list:
    """The arrays of an orbax item folder as orbax itself reads them (no jaxgest code involved)."""
    import orbax.checkpoint as ocp

    reader = ocp.StandardCheckpointer()
    try:
        return [np.asarray(x) for x in jax.tree_util.tree_leaves(reader.restore(pathlib.Path(state_dir).resolve()))]
    finally:
        reader.close()


def flip_bytes(step_dir, width: int = 32, places: int = 16):
    """Bit rot that still decodes, caught only by the checksum in the meta item: ``width`` bytes of the largest
    data file inverted at a place where orbax still reads every array, and reads different values.

    Where orbax puts each array in its data files depends on the order its parallel writes finish (sizes and
    layout differ from run to run), and some bytes of a data file are never read back, so a fixed offset can
    land where nothing changes or where the compressed stream no longer decodes. The place is therefore chosen
    by reading: the first of ``places`` evenly spaced offsets (from 1/3 of the file on) whose flip orbax reads
    without an error as different arrays.
    """
    state = step_dir / "state"
    before = _read_arrays(state)
    f = _data_files(step_dir)[0]
    orig = f.read_bytes()
    n = len(orig) - width
    for k in range(places):
        start = (n // 3 + k * n // places) % n
        b = bytearray(orig)
        b[start:start + width] = bytes(x ^ 0xFF for x in b[start:start + width])
        f.write_bytes(bytes(b))
        try:
            after = _read_arrays(state)
        except Exception:  # noqa: BLE001  (the stream no longer decodes: another corruption, try elsewhere)
            continue
        if any(not np.array_equal(x, y, equal_nan=True) for x, y in zip(before, after)):
            return
    f.write_bytes(orig)
    raise AssertionError(f"{f}: no place among {places} where a flip of {width} bytes still decodes")


def missing_state(step_dir):
    shutil.rmtree(step_dir / "state")


def garbage_meta(step_dir):
    (step_dir / "meta" / "metadata").write_text("{not json")


CORRUPTIONS = {"truncated": (truncate_data, "a data file is truncated or corrupted"),
               "flipped": (flip_bytes, "its arrays do not match the checksum saved with them"),
               "missing": (missing_state, "a file is missing"),
               "garbage_meta": (garbage_meta, "its metadata is not valid JSON")}


def toy_problem():
    params = {"w": jnp.zeros((64,), jnp.float32)}
    state = TrainState.create(apply_fn=None, params=params, tx=optax.adam(0.05))
    target = jnp.linspace(-1.0, 1.0, 64, dtype=jnp.float32)

    def step_fn(state, batch, key):
        noise = jax.random.normal(jax.random.fold_in(key, state.step), (64,)) * 0.01
        loss, g = jax.value_and_grad(lambda p: jnp.mean((p["w"] - target * batch + noise) ** 2))(state.params)
        return state.apply_gradients(grads=g), {"loss": loss}

    return state, jax.jit(step_fn, donate_argnums=(0,)), lambda i: jnp.float32(1.0 + 0.01 * i)


def subprocess_env():
    e = {k: v for k, v in os.environ.items() if not k.startswith(("XLA_", "JAX_PLATFORMS"))}
    e.update(JAX_PLATFORMS="cpu", PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    return e


def kill_when(code: str, marker: pathlib.Path, timeout=300.0):
    """Run ``python -c code``; SIGKILL it as soon as ``marker`` exists."""
    proc = subprocess.Popen([sys.executable, "-c", code], env=subprocess_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    try:
        while not marker.exists():
            assert proc.poll() is None, f"ended before the kill: {proc.stderr.read()[-2000:]}"
            assert time.monotonic() - t0 < timeout, "the write never started"
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL


def params_at(ckpt_dir: pathlib.Path, step: int) -> dict:
    """``{path: array}`` of the parameters and optimizer state restored from one checkpoint."""
    import orbax.checkpoint as ocp

    tree = ocp.StandardCheckpointer().restore((ckpt_dir / str(step) / "state").resolve())
    assert int(tree["step"]) == step
    return {jax.tree_util.keystr(p): np.asarray(x) for p, x in
            jax.tree_util.tree_flatten_with_path({"params": tree["params"], "opt": tree["opt_state"]})[0]}


def assert_identical(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)

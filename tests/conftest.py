"""Shared test configuration (STYLE.md): strict rank promotion, 4 fake CPU devices, a `key` fixture, data
paths, and the session's tiny trained models.

Devices. The process sees ``NUM_DEVICES`` = 4 fake CPU devices (``jax_num_cpu_devices``, set before the
backend starts), so the data-parallel tests run in-process (tests/test_parallel.py). Everything else keeps
running on ONE device: while the tests run, :func:`jaxgest.parallel.make_mesh` called without a device count
(training without ``--devices``) builds a 1-device mesh, as on a one-device machine; a test that wants every
device passes the count (``devices=4`` / ``--devices 4``) or uses the ``all_devices`` fixture, which restores
the package's own default (all visible devices).

Trained models. ``tiny_data`` (4 synthetic clips x 3 s, BVH + WAV) and the tiny TGST / ZeroEGGS workdirs
trained on it once per session (seed 0; TGST 4 + 4 steps, ZeroEGGS 4 steps; checkpoints every 2 steps, so
each stage keeps steps 2 and 4; metrics every step) are shared by the CLI, bad-input, faults,
determinism, pipeline and resume tests. They are READ-ONLY: a test that changes a workdir copies it first
(``copy_workdir``). Real-data tests read ../shared/data and skip cleanly when it is absent.
"""

from __future__ import annotations

import functools
import os
import pathlib
import shutil

import jax
import pytest

#: Fake CPU devices of the test process (the data-parallel tests use all of them).
NUM_DEVICES = 4
jax.config.update("jax_num_cpu_devices", NUM_DEVICES)  # before anything starts the backend

# Implicit rank promotion hides shape bugs: forbid it. Dtype promotion stays "standard": optax's own Adam
# (bias correction `b ** count` with an int32 count) is not "strict"-clean, so strict would test optax,
# not us; our modules cast explicitly instead.
jax.config.update("jax_numpy_rank_promotion", "raise")

from jaxgest import parallel  # noqa: E402  (after the device count is configured)
from tiny_models import train_tgst, train_zeggs  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[1]
SHARED = pathlib.Path(os.environ.get("JAXGEST_SHARED", REPO.parent / "shared")).resolve()
BANDAI = SHARED / "data" / "bandai-namco-1" / "data"
ZEGGS = SHARED / "data" / "speech-gesture" / "zeggs"
BEAT2 = SHARED / "data" / "speech-gesture" / "beat2"

#: The package's own ``make_mesh`` (default: every visible device).
ALL_DEVICES_MAKE_MESH = parallel.make_mesh


@functools.wraps(ALL_DEVICES_MAKE_MESH)
def _one_device_by_default(num_devices=None):
    return ALL_DEVICES_MAKE_MESH(1 if num_devices is None else num_devices)


parallel.make_mesh = _one_device_by_default


@pytest.fixture
def all_devices(monkeypatch):
    """Within the test, ``make_mesh()`` without a count uses every device again (the package's default)."""
    monkeypatch.setattr(parallel, "make_mesh", ALL_DEVICES_MAKE_MESH)
    assert jax.device_count() == NUM_DEVICES
    return NUM_DEVICES


@pytest.fixture
def key():
    return jax.random.key(0)


@pytest.fixture(scope="session")
def bandai_dir():
    if not BANDAI.is_dir():
        pytest.skip(f"real data not found at {BANDAI}")
    return BANDAI


@pytest.fixture(scope="session")
def zeggs_dir():
    if not ZEGGS.is_dir():
        pytest.skip(f"real data not found at {ZEGGS}")
    return ZEGGS


# ----- the session's tiny trained models -------------------------------------------------------------------

@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory) -> pathlib.Path:
    """The built-in synthetic dataset, 4 clips x 3 s (BVH + WAV); read-only."""
    from jaxgest.motion.synthetic import write_dataset

    folder = tmp_path_factory.mktemp("tiny") / "data"
    write_dataset(folder, clips=4, seconds=3, progress=False)
    return folder


@pytest.fixture(scope="session")
def tgst_trained(tiny_data, tmp_path_factory) -> tuple:
    """``(workdir, summary)``: tiny TGST trained on ``tiny_data`` (4 + 4 steps, checkpoints 2 and 4 per stage)
    and what ``train`` returned; read-only."""
    work = tmp_path_factory.mktemp("tiny_tgst") / "tgst"
    return work, train_tgst(tiny_data, work)


@pytest.fixture(scope="session")
def tgst_workdir(tgst_trained) -> pathlib.Path:
    """The tiny TGST workdir of ``tgst_trained``; read-only."""
    return tgst_trained[0]


@pytest.fixture(scope="session")
def zeggs_trained(tiny_data, tmp_path_factory) -> tuple:
    """``(workdir, summary)``: tiny ZeroEGGS trained on ``tiny_data`` (4 steps, checkpoints 2 and 4) and what
    ``train`` returned; read-only."""
    work = tmp_path_factory.mktemp("tiny_zeggs") / "zeggs"
    return work, train_zeggs(tiny_data, work)


@pytest.fixture(scope="session")
def zeggs_workdir(zeggs_trained) -> pathlib.Path:
    """The tiny ZeroEGGS workdir of ``zeggs_trained``; read-only."""
    return zeggs_trained[0]


@pytest.fixture(scope="session")
def zeggs_pca_workdir(zeggs_workdir, tiny_data, tmp_path_factory) -> pathlib.Path:
    """A copy of ``zeggs_workdir`` with a fitted style PCA (``jaxgest zeggs pca``); read-only."""
    from jaxgest import cli

    work = tmp_path_factory.mktemp("tiny_zeggs_pca") / "zeggs_pca"
    shutil.copytree(zeggs_workdir, work)
    assert cli.main(["zeggs", "pca", "--workdir", str(work), "--data", str(tiny_data), "--window", "1.0"]) == 0
    return work


@pytest.fixture
def copy_workdir(tmp_path):
    """``copy_workdir(src, name=None)``: a private copy of a shared workdir under this test's tmp_path."""

    def copy(src: pathlib.Path, name: str = None) -> pathlib.Path:
        dst = tmp_path / (name or src.name)
        shutil.copytree(src, dst)
        return dst

    return copy


@pytest.fixture(scope="session")
def tiny(tiny_data, tgst_workdir, zeggs_workdir) -> dict:
    """The shared data and workdirs with the files the CLI tests use: ``data``, ``tw`` (TGST), ``zw``
    (ZeroEGGS), ``content`` / ``style`` (BVH), ``wav``; all read-only."""
    return {"data": tiny_data, "tw": tgst_workdir, "zw": zeggs_workdir,
            "content": tiny_data / "greeting_neutral_0.bvh", "style": tiny_data / "greeting_sad_0.bvh",
            "wav": tiny_data / "greeting_neutral_0.wav"}

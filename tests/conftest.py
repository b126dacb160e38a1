"""Shared test configuration: strict rank promotion, 4 fake CPU devices, a `key` fixture, data paths, the
session's tiny trained models, test kinds and hypothesis profiles.

Kinds. ``tests/unit``, ``tests/property`` (hypothesis), ``tests/integration`` (CLI, subprocesses,
kill/resume, multi-device) and ``tests/research`` (checks of experiment results); helpers in ``tests/helpers``
(on the path). Every hypothesis test, wherever it lives, gets the ``property`` marker (``pytest -m property``).
Tests marked ``research`` (long model trainings) are left out of the default run (``pytest -m research``).

Hypothesis profiles: ``ci`` (the default: derandomized, no deadline, each test's own ``max_examples``) and
``thorough`` (ten times each test's examples, random): ``HYPOTHESIS_PROFILE=thorough pytest -m property``.

Devices. The process sees ``NUM_DEVICES`` = 4 fake CPU devices (``jax_num_cpu_devices``, set before the
backend starts), so the data-parallel tests run in-process (tests/integration/test_parallel.py). Everything else keeps
running on ONE device: while the tests run, :func:`jaxgest.runtime.parallel.make_mesh` called without a device count
(training without ``--devices``) builds a 1-device mesh, as on a one-device machine; a test that wants every
device passes the count (``devices=4`` / ``--devices 4``) or uses the ``all_devices`` fixture, which restores
the package's own default (all visible devices).

Trained models. ``tiny_data`` (4 synthetic clips x 3 s, BVH + WAV) and the tiny TGST / ZeroEGGS workdirs
trained on it once per session (seed 0; TGST 4 + 4 steps, ZeroEGGS 4 steps; checkpoints every 2 steps, so
each stage keeps steps 2 and 4; metrics every step) are shared by the CLI, bad-input, faults,
determinism, pipeline and resume tests, and with pytest-xdist by the workers too (built by the first
worker that needs them, under a file lock). They are READ-ONLY: a test that changes a workdir copies it first
(``copy_workdir``). Real-data tests read ../shared/data and skip cleanly when it is absent.

Order. The costliest files run first (``COSTLIEST_FIRST``), so ``-n 2 --dist loadfile`` ends with short
files on both workers instead of a long one on one of them.
"""

from __future__ import annotations

import fcntl
import functools
import json
import os
import pathlib
import shutil

import hypothesis
import jax
import pytest

#: Fake CPU devices of the test process (the data-parallel tests use all of them).
NUM_DEVICES = 4
jax.config.update("jax_num_cpu_devices", NUM_DEVICES)  # before anything starts the backend

# Implicit rank promotion hides shape bugs: forbid it. Dtype promotion stays "standard": optax's own Adam
# (bias correction `b ** count` with an int32 count) is not "strict"-clean, so strict would test optax,
# not us; our modules cast explicitly instead.
jax.config.update("jax_numpy_rank_promotion", "raise")

hypothesis.settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
hypothesis.settings.register_profile("thorough", deadline=None, print_blob=True)
hypothesis.settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))  # before the test modules import
#: each test's max_examples is multiplied by this (the profiles cannot raise a test's own explicit setting)
THOROUGH_FACTOR = 10

from jaxgest.runtime import parallel  # noqa: E402  (after the device count is configured)
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


# ----- order of the files (pytest-xdist workers) ----------------------------------------------------------

#: The costliest test files, costliest first (CPU seconds of the file on one worker, session models included
#: where the file is the first to need them; measured with ``--durations`` per file). ``-n 2 --dist loadfile``
#: hands whole files to the two workers in collection order, so the long files start first and the short
#: ones fill in at the end (longest-processing-time-first). Without this order xdist sorts the files by
#: their number of tests, which put the three longest (few tests each) on one worker at the end.
COSTLIEST_FIRST = (
    "test_zeggs_style_control.py",  # 100 s: its own 1,200-step model; needs none of the session's models
    "test_parallel.py",  # 135 s with the session's tiny models (whoever needs them first builds them)
    "test_tgst_transfer.py",  # 90
    "test_bench_harness.py",  # 73
    "test_zeggs_model.py",  # 68
    "test_resume_kill.py",  # 67 (subprocesses)
    "test_tgst_api.py",  # 50
    "test_cli_bad_input.py",  # 45
    "test_faults_checkpoints.py",  # 40
    "test_zeggs_api.py",  # 40
    "test_zeggs_quant.py",  # 38
    "test_invariance.py",  # 30
    "test_determinism.py",  # 27
)


def _warm_numba_cache():
    """Compile librosa's numba-cached functions once, in this process, before any xdist worker starts.

    On a fresh install two workers would otherwise compile and write the same numba cache files at the same
    time, which can leave a corrupt cache entry (seen once: every later ``peak_pick`` call segfaulted).
    """
    import numpy as np

    from jaxgest.audio import log_mel_energy
    from jaxgest.metrics.generation import onset_times

    y = np.sin(np.linspace(0.0, 800.0, 16000)).astype(np.float32) * np.repeat(np.arange(8) % 2, 2000)
    onset_times(y, 16000)
    log_mel_energy(y, 16000)


def pytest_configure(config):
    if hasattr(config.option, "loadscopereorder"):  # pytest-xdist: keep the order of COSTLIEST_FIRST
        config.option.loadscopereorder = False
    if not hasattr(config, "workerinput"):  # the controller (or a plain run): before any worker exists
        _warm_numba_cache()


#: tests/slow.txt names its tests relative to the repository root (REPO)
SLOW_LIST = REPO / "tests" / "slow.txt"


def slow_entries() -> tuple[set, set]:
    """``(files, (file, function) pairs)`` of tests/slow.txt: the tests marked ``slow`` besides those that
    carry the marker themselves (left out of the README's test command, run by .ci/run after it)."""
    files, functions = set(), set()
    for line in SLOW_LIST.read_text().splitlines():
        entry = line.split("#", 1)[0].strip()
        if entry:
            path, _, function = entry.partition("::")
            (functions.add((path, function)) if function else files.add(path))
    return files, functions


def is_listed_slow(item, entries) -> bool:
    """Whether tests/slow.txt (``entries``: :func:`slow_entries`) names the test ``item`` (by file or function)."""
    files, functions = entries
    path = item.path.relative_to(REPO).as_posix()
    function = getattr(item, "originalname", None) or item.name.split("[")[0]
    return path in files or (path, function) in functions


def _scale_examples(function, factor: int) -> None:
    """Multiply a hypothesis test's own ``max_examples`` (its settings live on the wrapped function)."""
    own = getattr(function, "_hypothesis_internal_use_settings", None)
    if own is not None:
        function._hypothesis_internal_use_settings = hypothesis.settings(own, max_examples=own.max_examples * factor)


def pytest_collection_modifyitems(config, items):
    thorough = hypothesis.settings._current_profile == "thorough"
    scaled = set()
    for item in items:
        function = getattr(item, "function", None)
        if function is not None and hypothesis.is_hypothesis_test(function):
            item.add_marker(pytest.mark.property)
            if thorough and id(function) not in scaled:  # parametrized tests share one function
                scaled.add(id(function))
                _scale_examples(function, THOROUGH_FACTOR)
    entries = slow_entries()
    for item in items:
        if is_listed_slow(item, entries):
            item.add_marker(pytest.mark.slow)
    rank = {name: i for i, name in enumerate(COSTLIEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the others keep their order


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

def _built_once(tmp_path_factory, name: str, build) -> tuple:
    """``(folder, result)``: ``build(folder)`` run once per test session and its JSON-able result. With
    pytest-xdist the workers share it: the first worker that needs it builds it under a file lock in the
    session's common temporary folder, the others wait for the lock and read it (a trained model costs one
    worker, not each). Read-only for everyone."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, above each worker's own popen-gwN
    folder, done = root / "built" / name, root / "built" / f"{name}.json"
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(root / "built" / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not done.is_file():
            shutil.rmtree(folder, ignore_errors=True)
            result = build(folder)
            done.write_text(json.dumps(result))  # after the build: a crashed build is rebuilt by the next
        return folder, json.loads(done.read_text())


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory) -> pathlib.Path:
    """The built-in synthetic dataset, 4 clips x 3 s (BVH + WAV); read-only."""
    from jaxgest.motion.synthetic import write_dataset

    def build(folder):
        write_dataset(folder, clips=4, seconds=3, progress=False)

    return _built_once(tmp_path_factory, "tiny_data", build)[0]


@pytest.fixture(scope="session")
def tgst_trained(tiny_data, tmp_path_factory) -> tuple:
    """``(workdir, summary)``: tiny TGST trained on ``tiny_data`` (4 + 4 steps, checkpoints 2 and 4 per stage)
    and what ``train`` returned; read-only."""
    return _built_once(tmp_path_factory, "tgst", lambda work: train_tgst(tiny_data, work))


@pytest.fixture(scope="session")
def tgst_workdir(tgst_trained) -> pathlib.Path:
    """The tiny TGST workdir of ``tgst_trained``; read-only."""
    return tgst_trained[0]


@pytest.fixture(scope="session")
def zeggs_trained(tiny_data, tmp_path_factory) -> tuple:
    """``(workdir, summary)``: tiny ZeroEGGS trained on ``tiny_data`` (4 steps, checkpoints 2 and 4) and what
    ``train`` returned; read-only."""
    return _built_once(tmp_path_factory, "zeggs", lambda work: train_zeggs(tiny_data, work))


@pytest.fixture(scope="session")
def zeggs_workdir(zeggs_trained) -> pathlib.Path:
    """The tiny ZeroEGGS workdir of ``zeggs_trained``; read-only."""
    return zeggs_trained[0]


@pytest.fixture(scope="session")
def zeggs_pca_workdir(zeggs_workdir, tiny_data, tmp_path_factory) -> pathlib.Path:
    """A copy of ``zeggs_workdir`` with a fitted style PCA (``jaxgest zeggs pca``); read-only."""
    from jaxgest import cli

    def build(work):
        shutil.copytree(zeggs_workdir, work)
        assert cli.main(["zeggs", "pca", "--workdir", str(work), "--data", str(tiny_data), "--window", "1.0"]) == 0

    return _built_once(tmp_path_factory, "zeggs_pca", build)[0]


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

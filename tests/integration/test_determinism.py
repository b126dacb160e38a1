"""Same seed, same machine -> bit-identical training losses, checkpoints and CLI outputs.

Two trainings of each model with the same seed on the tiny synthetic data (the session's shared workdir and
a second run trained the same way, tests/helpers/tiny_models.py) must write the same
``metrics.jsonl`` losses (every field but the wall-clock ``steps_per_s``) and the same checkpointed
parameters, bit for bit; ``tgst transfer`` and ``zeggs generate`` must write byte-identical BVH files from
either workdir. A different seed must change them (so the comparison can fail). Batches are pure functions
of ``(seed, step)``, the PRNG keys are explicit, and XLA on one CPU runs the same program in the same
order, so nothing here needs a tolerance. (Across machines or device counts only float-tolerance
agreement is promised: see tests/integration/test_parallel.py.)
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from jaxgest import cli

from tiny_models import TINY_SEED, train_tgst, train_zeggs


@pytest.fixture(scope="module")
def data(tiny_data):
    return tiny_data


def losses(workdir) -> list:
    return [{k: v for k, v in json.loads(x).items() if k != "steps_per_s"}
            for x in (workdir / "metrics.jsonl").read_text().splitlines()]


def restored(ckpt_dir) -> dict:
    import orbax.checkpoint as ocp

    step = max(int(p.name) for p in ckpt_dir.iterdir() if p.name.isdigit())
    tree = ocp.StandardCheckpointer().restore((ckpt_dir / str(step) / "state").resolve())
    return {jax.tree_util.keystr(p): np.asarray(x) for p, x in jax.tree_util.tree_flatten_with_path(tree)[0]}


def assert_same_arrays(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def run(argv, capsys) -> None:
    capsys.readouterr()
    rc = cli.main([str(a) for a in argv])
    assert rc == 0, capsys.readouterr().err


@pytest.fixture(scope="module")
def tgst_runs(data, tgst_workdir, tmp_path_factory):
    """``a``: the session's workdir; ``b``: trained the same way; ``other``: another seed."""
    root = tmp_path_factory.mktemp("tgst_det")
    (root / "a").symlink_to(tgst_workdir, target_is_directory=True)
    for name, seed in (("b", TINY_SEED), ("other", TINY_SEED + 1)):
        train_tgst(data, root / name, seed=seed)
    return root


@pytest.mark.slow
def test_tgst_training_is_bit_identical(tgst_runs):
    a, b, other = (tgst_runs / n for n in ("a", "b", "other"))
    assert losses(a) == losses(b) and len(losses(a)) == 8
    assert losses(a) != losses(other)
    for stage in ("autoencoder", "transformer"):
        assert_same_arrays(restored(a / "checkpoints" / stage), restored(b / "checkpoints" / stage))


@pytest.mark.slow
def test_tgst_transfer_is_bit_identical(tgst_runs, data, tmp_path, capsys):
    content, style = data / "greeting_neutral_0.bvh", data / "greeting_sad_0.bvh"
    outs = {}
    for i, name in enumerate(("a", "a", "b", "other")):
        out = tmp_path / f"{name}{i}.bvh"
        run(["tgst", "transfer", "--workdir", tgst_runs / name, "--content", content, "--style", style,
             "--out", out], capsys)
        outs[f"{name}{i}"] = out.read_bytes()
    assert outs["a0"] == outs["a1"] == outs["b2"]
    assert outs["a0"] != outs["other3"]


@pytest.fixture(scope="module")
def zeggs_runs(data, zeggs_workdir, tmp_path_factory):
    """``a``: the session's workdir; ``b``: trained the same way."""
    root = tmp_path_factory.mktemp("zeggs_det")
    (root / "a").symlink_to(zeggs_workdir, target_is_directory=True)
    train_zeggs(data, root / "b")
    return root


@pytest.mark.slow
def test_zeggs_training_is_bit_identical(zeggs_runs):
    a, b = zeggs_runs / "a", zeggs_runs / "b"
    assert losses(a) == losses(b) and [r["step"] for r in losses(a)] == [1, 2, 3, 4]
    assert_same_arrays(restored(a / "checkpoints" / "zeggs"), restored(b / "checkpoints" / "zeggs"))
    for f in ("pose_stats.json", "speech_stats.json"):
        assert (a / f).read_bytes() == (b / f).read_bytes()


@pytest.mark.slow
def test_zeggs_generate_is_bit_identical_per_seed(zeggs_runs, data, tmp_path, capsys):
    outs = {}
    for i, (name, seed) in enumerate((("a", 0), ("a", 0), ("b", 0), ("a", 1))):
        out = tmp_path / f"{name}{seed}_{i}.bvh"
        run(["zeggs", "generate", "--workdir", zeggs_runs / name, "--audio", data / "greeting_tense_0.wav",
             "--style", data / "greeting_sad_0.bvh", "--seed", seed, "--out", out], capsys)
        outs[i] = out.read_bytes()
    assert outs[0] == outs[1] == outs[2]
    assert outs[0] != outs[3]  # another seed samples another style embedding

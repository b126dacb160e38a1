"""Training you can watch (issue 60, part B) through the command line: ``--eval-every N --eval-data DIR`` (a
held-out loss in metrics.jsonl), ``--tb DIR`` (the same numbers as TensorBoard events), ``--profile DIR`` (a
jax.profiler trace) and ``jaxgest plot``; the flags' one-line errors. On the session's tiny data."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jaxgest import cli
from tb_events import scalar_events


@pytest.fixture(scope="module")
def heldout(tmp_path_factory):
    """Two held-out synthetic folders (scripts of other seeds than the training data's)."""
    from jaxgest.motion.synthetic import write_dataset

    out = []
    for seed in (1, 2):
        d = tmp_path_factory.mktemp(f"heldout{seed}")
        write_dataset(d, clips=3, seconds=3, seed=seed, progress=False)
        out.append(d)
    return out


def _lines(workdir):
    return [json.loads(x) for x in (workdir / "metrics.jsonl").read_text().splitlines()]


def _scalars(folder):
    """{(run, tag, step): value} of the TensorBoard event files under ``folder``."""
    return {(run, tag, step): value for run, tag, step, value in scalar_events(folder)}


@pytest.mark.slow
def test_zeggs_train_watched(tiny, heldout, tmp_path, capsys):
    pytest.importorskip("tensorboardX")
    w, tb, prof = tmp_path / "w", tmp_path / "tb", tmp_path / "prof"
    assert cli.main(["zeggs", "train", "--data", str(tiny["data"]), "--workdir", str(w), "--steps", "4",
                     "--log-every", "1", "--eval-every", "2", "--eval-data", str(heldout[0]), "--tb", str(tb),
                     "--profile", str(prof)]) == 0
    assert "(held-out " in capsys.readouterr().out
    lines = _lines(w)
    assert [r["step"] for r in lines] == [1, 2, 3, 4]
    held = {r["step"]: r["eval_loss"] for r in lines if "eval_loss" in r}
    assert sorted(held) == [2, 4] and all(np.isfinite(v) for v in held.values())
    assert all(r["eval_loss"] != r["loss"] for r in lines if "eval_loss" in r)
    # TensorBoard has the numbers of metrics.jsonl: training ones under train/, held-out ones under eval/
    got = _scalars(tb)
    for r in lines:
        assert got[("train", "zeggs/loss", r["step"])] == pytest.approx(r["loss"], rel=1e-6)
        if "eval_loss" in r:
            assert got[("eval", "zeggs/loss", r["step"])] == pytest.approx(r["eval_loss"], rel=1e-6)
    assert len(list(prof.rglob("*.xplane.pb"))) == 1

    # another held-out folder gives another held-out loss (the control: it is computed on that data), and the
    # training losses depend neither on the held-out data nor on the TensorBoard writer or the trace
    w2 = tmp_path / "w2"
    assert cli.main(["zeggs", "train", "--data", str(tiny["data"]), "--workdir", str(w2), "--steps", "4",
                     "--log-every", "1", "--eval-every", "4", "--eval-data", str(heldout[1])]) == 0
    other = _lines(w2)
    assert other[-1]["eval_loss"] != held[4]
    assert [r["loss"] for r in other] == [r["loss"] for r in lines]
    capsys.readouterr()

    # plot: both runs, train and held-out curves
    assert cli.main(["plot", str(w), str(w2), "--out", str(tmp_path / "curves.png"), "--labels", "a,b"]) == 0
    assert (tmp_path / "curves.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.slow
def test_tgst_train_held_out_per_stage(tiny, heldout, tmp_path, capsys):
    w = tmp_path / "w"
    assert cli.main(["tgst", "train", "--data", str(tiny["data"]), "--workdir", str(w), "--steps", "2",
                     "--log-every", "1", "--eval-every", "2", "--eval-data", str(heldout[0])]) == 0
    out = capsys.readouterr().out
    assert out.count("(held-out ") == 2, out
    lines = _lines(w)
    for stage in ("autoencoder", "transformer"):
        rows = [r for r in lines if r["stage"] == stage]
        assert [r["step"] for r in rows] == [1, 2]
        assert "eval_loss" not in rows[0] and np.isfinite(rows[1]["eval_loss"])
        assert {k for k in rows[1] if k.startswith("eval_")} == {"eval_" + k for k in rows[0]
                                                                 if k not in ("step", "stage", "steps_per_s")
                                                                 and isinstance(rows[0][k], float)}


def test_watch_flags_errors(tiny, heldout, tmp_path, capsys):
    (tmp_path / "file").write_text("")
    base = ["zeggs", "train", "--data", str(tiny["data"]), "--steps", "2"]
    cases = [
        (["--eval-every", "2"], "--eval-every and --eval-data go together"),
        (["--eval-data", str(heldout[0])], "--eval-every and --eval-data go together"),
        (["--eval-every", "3", "--log-every", "2", "--eval-data", str(heldout[0])],
         "--eval-every 3 must be a multiple of --log-every 2"),
        (["--eval-every", "0", "--eval-data", str(heldout[0])],
         "eval_every must be a positive number of steps"),
        (["--eval-every", "2", "--log-every", "1", "--eval-data", str(tmp_path / "none")],
         "--eval-data needs a folder"),
        (["--tb", str(tmp_path / "file")], "--tb needs a folder, and this is a file"),
        (["--profile", str(tmp_path / "file")], "--profile needs a folder, and this is a file"),
    ]
    for k, (args, why) in enumerate(cases):
        w = tmp_path / f"w{k}"
        for command in (base, ["tgst", "train", "--data", str(tiny["data"]), "--steps", "2"]):
            assert cli.main([*command, "--workdir", str(w), *args]) == 2, args
            err = capsys.readouterr().err
            assert why in err and len(err.strip().splitlines()) == 1, (args, err)
            assert not w.exists()  # refused before anything was written

"""``jaxgest zeggs evaluate --claims`` end to end on the session's tiny ZeroEGGS model: a stamped results file with
criteria 1, 3, 4 (and 5 with --speech), a markdown table with GT and MM beside the model, the GT substitute
holding, and one-line errors (exit 2) for bad input. Also leave-one-style-out training (``exclude_styles``)."""

from __future__ import annotations

import json

import pytest

from jaxgest import cli
from jaxgest.runtime.provenance import read_results


@pytest.fixture(scope="module")
def claim_data(tmp_path_factory):
    """Training scripts (seed 0) and a held-out script set (seed 1): 2 contents x 7 styles x 3 s."""
    from jaxgest.motion.synthetic import write_dataset

    root = tmp_path_factory.mktemp("claims_cli")
    write_dataset(root / "train", clips=14, seconds=3, seed=0, progress=False)
    write_dataset(root / "held", clips=14, seconds=3, seed=1, progress=False)
    return root


def test_claims_cli_writes_stamped_results(zeggs_workdir, claim_data, tmp_path, capsys):
    out = tmp_path / "claims.json"
    wav = claim_data / "held" / "greeting_neutral_0.wav"
    rc = cli.main(["zeggs", "evaluate", "--workdir", str(zeggs_workdir), "--data", str(claim_data / "train"),
                   "--claims", "--heldout", str(claim_data / "held"), "--speech", str(wav),
                   "--segment-seconds", "1.5", "--speech-styles", "sad,tense", "--json", str(out)])
    assert rc == 0
    doc = read_results(out)  # refuses an unstamped file
    r = doc["results"]
    assert doc["stamp"]["config"]["heldout"] == [str(claim_data / "held")]
    assert r["claims"]["clips"] == 14 and r["claims"]["source"] == "generated"
    for k in ("style_portrayal", "realism", "appropriateness"):
        assert isinstance(r["claims"][k]["holds"], bool)
    assert set(r["real_speech"]["styles"]) == {"sad", "tense"} and r["real_speech"]["segments"] == 2
    text = capsys.readouterr().out
    assert "| claim | model | GT | MM | verdict |" in text and "Real speech" in text


def test_claims_cli_gt_substitute_holds(zeggs_workdir, claim_data, tmp_path, capsys):
    out = tmp_path / "gt.json"
    rc = cli.main(["zeggs", "evaluate", "--workdir", str(zeggs_workdir), "--data", str(claim_data / "train"),
                   "--claims", "--heldout", str(claim_data / "held"), "--substitute", "gt", "--json", str(out)])
    assert rc == 0
    r = read_results(out)["results"]["claims"]
    assert r["source"] == "gt" and r["style_portrayal"]["holds"] and r["realism"]["holds"]


@pytest.mark.parametrize("extra, message", [
    (["--heldout", "H"], "--heldout: only with --claims"),
    (["--claims"], "--claims needs held-out data"),
    (["--claims", "--heldout", "MISSING"], "MISSING: no such held-out data folder"),
    (["--claims", "--speech", "MISSING.wav"], "MISSING.wav: no such speech file"),
    (["--claims", "--heldout", "H", "--probe-seeds", "2"], "--probe-seeds: not with --claims"),
    (["--claims", "--heldout-seeds", "-1"], "--heldout-seeds must be >= 0"),
    (["--style-scale", "2"], "--style-scale: only with --claims"),
    (["--claims", "--heldout", "H", "--style-scale", "0"], "--style-scale must be finite and > 0"),
    (["--claims", "--speech", "WAV", "--speech-styles", "sad,happy"], "no training clip of the --speech-styles happy"),
])
def test_claims_cli_bad_input(zeggs_workdir, claim_data, tmp_path, capsys, extra, message):
    named = {"H": str(claim_data / "held"), "WAV": str(claim_data / "held" / "greeting_sad_0.wav")}
    extra = [named.get(a, str(tmp_path / a) if a.startswith("MISSING") else a) for a in extra]
    rc = cli.main(["zeggs", "evaluate", "--workdir", str(zeggs_workdir), "--data", str(claim_data / "train"),
                   "--json", str(tmp_path / "x.json"), *extra])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and message in err, err
    assert not (tmp_path / "x.json").exists()


def test_train_exclude_styles(tiny_data, tmp_path, capsys):
    """Leave-one-style-out: the excluded style's clips are not trained on and the workdir records it."""
    from tiny_models import train_zeggs

    full = train_zeggs(tiny_data, tmp_path / "full", steps=1)
    left = train_zeggs(tiny_data, tmp_path / "left", steps=1, overrides={"train.exclude_styles": ("sad",)})
    assert left["sequences"] == full["sequences"] * 3 // 4  # 4 clips of 4 styles, one left out
    cfg = json.loads((tmp_path / "left" / "config.json").read_text())
    assert "sad" in json.dumps(cfg)
    rc = cli.main(["zeggs", "train", "--data", str(tiny_data), "--workdir", str(tmp_path / "bad"), "--preset", "tiny",
                   "--steps", "1", "--override", "train.exclude_styles=happy"])
    err = capsys.readouterr().err
    assert rc == 2 and "exclude_styles names style(s) the data does not have: happy" in err


@pytest.mark.realdata
def test_claims_cli_real_speech(zeggs_workdir, zeggs_dir, claim_data, tmp_path, capsys):
    """Criterion 5 on the real ZEGGS recording (68.8 s, 16 kHz): segments in two styles, BeatAlign vs MM."""
    wav = zeggs_dir / "067_Speech_2_x_1_0.wav"
    out = tmp_path / "speech.json"
    rc = cli.main(["zeggs", "evaluate", "--workdir", str(zeggs_workdir), "--data", str(claim_data / "train"),
                   "--claims", "--speech", str(wav), "--segment-seconds", "20", "--json", str(out)])
    assert rc == 0
    rs = read_results(out)["results"]["real_speech"]
    assert rs["segments"] == 3 and set(rs["styles"]) == {"energetic", "sad"}  # 68.8 s: 20 + 20 + 20 (+ 8.8 dropped)
    for x in rs["styles"].values():
        assert 0.0 <= x["recognised"] <= 1.0 and x["generated"]["n"] == 3

"""Speech -> ZeroEGGS -> TGST chain (jaxgest.pipeline, ``jaxgest pipeline``) on tiny synthetic models."""

from __future__ import annotations

import numpy as np
import pytest
import soundfile as sf

from jaxgest import cli
from jaxgest.motion import bvh, kinematics, root_motion


@pytest.fixture(scope="module")
def workdirs(tiny):
    """The session's synthetic data and tiny ZeroEGGS / TGST workdirs (read-only)."""
    return tiny["data"], tiny["zw"], tiny["tw"]


def test_pipeline_api_output_on_style_rig_with_audio_length(workdirs, zeggs_dir):
    from jaxgest.pipeline import speech_to_styled_gestures

    data, zw, tw = workdirs
    wav = sorted(data.glob("*.wav"))[0]
    real_style = bvh.load(zeggs_dir / "067_Speech_2_x_1_0.bvh")  # 75-joint rig at 30 fps
    neutral = bvh.load(sorted(data.glob("*.bvh"))[0])
    styled, generated, times = speech_to_styled_gestures(wav, real_style, zeggs_workdir=zw, tgst_workdir=tw,
                                                         zeggs_style=neutral)
    info = sf.info(str(wav))
    assert styled.skeleton.names == real_style.skeleton.names and styled.fps == real_style.fps
    assert styled.num_frames == round(info.frames / info.samplerate * real_style.fps)
    assert generated.skeleton.names == neutral.skeleton.names
    assert np.all(np.isfinite(styled.rotations)) and set(times) == {"load_s", "zeggs_s", "tgst_s"}
    feet = root_motion.foot_joints(styled.skeleton)
    np.testing.assert_allclose(kinematics.forward_kinematics(styled)[:, feet, 1].min(axis=1), 0.0, atol=1e-4)


def test_pipeline_cli(workdirs, tmp_path, capsys):
    data, zw, tw = workdirs
    wav = sorted(data.glob("*.wav"))[1]
    style = sorted(data.glob("*.bvh"))[2]
    out = tmp_path / "o.bvh"
    argv = ["pipeline", "--audio", str(wav), "--zeggs-workdir", str(zw), "--tgst-workdir", str(tw),
            "--style", str(style), "--out", str(out)]
    assert cli.main(argv) == 0
    m = bvh.load(out)
    assert m.skeleton.names == bvh.load(style).skeleton.names
    # swapped workdirs: a clear one-line error, no output
    bad = tmp_path / "bad.bvh"
    assert cli.main(["pipeline", "--audio", str(wav), "--zeggs-workdir", str(tw), "--tgst-workdir", str(zw),
                     "--style", str(style), "--out", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("jaxgest: ") and "\n" not in err and not bad.exists()

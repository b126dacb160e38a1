"""Speech in the HTML viewer (issue 60): jaxgest.viewer.encode_audio's window and encodings, the page's
policy and size, and `jaxgest render --audio` errors. The page playing it runs in a browser in
tests/integration/test_viewer_browser.py."""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
import soundfile as sf

from jaxgest import viewer
from jaxgest.motion import bvh
from jaxgest.motion.synthetic import CONTENTS, render_clip
from jaxgest.runtime.errors import AudioError, DataError

SR = viewer.AUDIO_RATE


@pytest.fixture(scope="module")
def speech():
    """A 4 s synthetic clip at 60 fps and its speech-like audio (16 kHz)."""
    motion, audio, sr = render_clip(CONTENTS["greeting"].with_seed(0, 4.0), "neutral", seed=0)
    assert sr == SR and audio.size == 4 * SR
    return motion, np.asarray(audio, np.float32)


@pytest.fixture
def pcm(monkeypatch):
    """The WAV fallback (exact up to 16-bit rounding), as where libsndfile has no Opus encoder."""
    monkeypatch.setattr(viewer, "_opus_available", lambda: False)


def _data(page: str) -> dict:
    return json.loads(re.search(r'id="jaxgest-data">(.*?)</script>', page, re.S)[1])


def _csp(page: str) -> str:
    return re.search(r'http-equiv="Content-Security-Policy" content="([^"]*)"', page)[1]


def _corr(a, b):
    return float(np.corrcoef(a, b)[0, 1])


def test_page_policy_and_embedding(speech, tmp_path):
    motion, audio = speech
    sf.write(tmp_path / "s.wav", audio, SR)
    silent = viewer.html_page([motion])
    page = viewer.html_page([motion], audio=tmp_path / "s.wav")
    # without speech the policy is unchanged; with it, media from data: URIs only, still no request at all
    assert _csp(silent) == viewer.CSP and "media-src" not in silent and _data(silent)["audio"] is None
    assert _csp(page) == ("default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                          "media-src data:")
    assert not re.search(r"https?://", page) and "{{" not in page
    rec = _data(page)["audio"]
    assert rec["src"].startswith("data:audio/ogg;base64,") and rec["codec"] == "opus"
    assert rec["source"] == "s.wav" and rec["offset"] == 0 and rec["sampleRate"] == SR
    assert rec["duration"] == pytest.approx(motion.duration) and rec["speechSeconds"] == pytest.approx(4.0)
    # compact: Opus at 16 kHz is under 6 kB per second (16-bit PCM would be 32 kB), base64 included
    assert rec["bytes"] < 6000 * motion.duration
    assert len(page) - len(silent) < 1.4 * 6000 * motion.duration
    # it is the speech: the decoded window has the source's samples, and not shifted ones (the control)
    got = viewer.decode_audio(rec)
    assert got.shape == (round(motion.duration * SR),)
    assert _corr(got, audio) > 0.9 and abs(_corr(got[:-SR // 4], audio[SR // 4:])) < 0.5


def test_offset_window_is_exact_in_the_wav_fallback(speech, pcm):
    motion, audio = speech
    n = round(motion.duration * SR)
    q = 1 / 32767 + 1e-6  # 16-bit rounding
    rec = viewer.encode_audio((audio, SR), motion.duration, offset=0.5)  # skip the speech's first 0.5 s
    assert rec["codec"] == "pcm16" and rec["src"].startswith("data:audio/wav;base64,")
    assert rec["bytes"] == 44 + 2 * n and rec["offset"] == 0.5
    got = viewer.decode_audio(rec)
    assert got.shape == (n,)
    np.testing.assert_allclose(got[:n - SR // 2], audio[SR // 2:], atol=q)
    assert not got[n - SR // 2:].any()  # the speech ended: silence to the end of the motion
    got = viewer.decode_audio(viewer.encode_audio((audio, SR), motion.duration, offset=-0.25))
    assert not got[:SR // 4].any()  # the speech starts 0.25 s into the motion
    np.testing.assert_allclose(got[SR // 4:], audio[:n - SR // 4], atol=q)
    # a longer motion than speech, another rate and stereo: resampled to 16 kHz, mixed down, padded
    stereo = np.stack([audio, audio], axis=1)
    got = viewer.decode_audio(viewer.encode_audio((stereo[::2], SR // 2), 6.0))
    assert got.shape == (6 * SR,) and not got[4 * SR + 8:].any()
    assert _corr(got[:4 * SR], audio) > 0.5  # half the rate keeps the speech's low half


def test_opus_keeps_the_offset(speech):
    motion, audio = speech
    got = viewer.decode_audio(viewer.encode_audio((audio, SR), 3.0, offset=0.5))
    assert got.shape == (3 * SR,)
    assert _corr(got, audio[SR // 2:SR // 2 + 3 * SR]) > 0.9
    assert abs(_corr(got, audio[:3 * SR])) < 0.5  # control: the unshifted speech does not match


def test_bad_speech(speech, tmp_path):
    motion, audio = speech
    with pytest.raises(AudioError, match="no such audio file"):
        viewer.encode_audio(tmp_path / "missing.wav", 4.0)
    (tmp_path / "text.wav").write_text("not audio")
    with pytest.raises(AudioError, match=r"text\.wav: unreadable audio"):
        viewer.encode_audio(tmp_path / "text.wav", 4.0)
    with pytest.raises(DataError, match="outside the motion"):
        viewer.encode_audio((audio, SR), 4.0, offset=5.0)
    with pytest.raises(DataError, match="outside the motion"):
        viewer.encode_audio((audio, SR), 4.0, offset=-4.0)
    with pytest.raises(AudioError, match="finite"):
        viewer.encode_audio((np.full(100, np.nan, np.float32), SR), 4.0)


def test_render_cli_audio(speech, tmp_path, capsys):
    from jaxgest.cli import main

    motion, audio = speech
    bvh.save(motion, tmp_path / "c.bvh")
    sf.write(tmp_path / "s.wav", audio, SR)
    (tmp_path / "text.wav").write_text("not audio")

    def _cli(*args):
        rc = main([str(a) for a in args])
        cap = capsys.readouterr()
        return SimpleNamespace(returncode=rc, stdout=cap.out, stderr=cap.err)

    r = _cli("render", tmp_path / "c.bvh", "--out", tmp_path / "v.html", "--audio", tmp_path / "s.wav",
             "--audio-offset", "0.25")
    assert r.returncode == 0, r.stderr
    rec = _data((tmp_path / "v.html").read_text())["audio"]
    assert rec["offset"] == 0.25 and rec["source"] == "s.wav"
    for args, why in (
            (("--out", tmp_path / "x.html", "--audio", tmp_path / "none.wav"),
             "none.wav: no such audio file"),
            (("--out", tmp_path / "x.html", "--audio", tmp_path / "text.wav"), "text.wav: unreadable audio"),
            (("--out", tmp_path / "x.html", "--audio", tmp_path), "no such audio file"),
            (("--out", tmp_path / "x.html", "--audio", tmp_path / "s.wav", "--audio-offset", "9"),
             "s.wav: an offset of 9 s puts the speech"),
            (("--out", tmp_path / "x.gif", "--audio", tmp_path / "s.wav"), "name the output .html"),
            (("--out", tmp_path / "x.html", "--audio-offset", "1"), "--audio-offset without --audio")):
        r = _cli("render", tmp_path / "c.bvh", *args)
        assert r.returncode == 2 and why in r.stderr, (args, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "x.html").exists() and not (tmp_path / "x.gif").exists()

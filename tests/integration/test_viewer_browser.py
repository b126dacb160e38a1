"""The HTML viewer in a real browser: headless Chromium (the system package) opens a generated page from disk
(file://), driven over the DevTools protocol (tests/helpers/browser_testing.py, standard library only).

Checks (issue 40): (a) every panel has skeleton pixels (the left/right bone colours), (b) screenshots at two
times differ inside every panel, (c) the page's frame count, frame rate and duration of each clip equal the
BVH file's, and its decoded positions equal forward kinematics to 0.1 mm, (d) no network request but the
page itself and no JavaScript error. Skipped, with the reason, when no Chromium is installed.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from browser_testing import Browser, find_chromium

from jaxgest.motion import bvh
from jaxgest.motion.datasets import resample_motion
from jaxgest.motion.kinematics import forward_kinematics
from jaxgest.motion.synthetic import CONTENTS, render_clip
from jaxgest.render import COLORS
from jaxgest.viewer import CM_TO_M, render_html

CHROMIUM = find_chromium()
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not found (apt-get install chromium-headless-shell; "
           ".ci/run installs it when it can)")

WIDTH, HEIGHT = 1200, 560


def _rgb(hex_color):
    return np.array([int(hex_color[i:i + 2], 16) for i in (1, 3, 5)], np.int32)


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """Three clips of different lengths and frame rates, written as BVH, read back, shown side by side."""
    d = tmp_path_factory.mktemp("viewer")
    made = [render_clip(CONTENTS["greeting"].with_seed(0, 2.0), "neutral", seed=0)[0],
            resample_motion(render_clip(CONTENTS["directions"].with_seed(0, 3.0), "energetic", seed=0)[0],
                            30.0),
            render_clip(CONTENTS["greeting"].with_seed(1, 2.5), "sad", seed=1)[0]]
    motions = []
    for k, m in enumerate(made):
        bvh.save(m, d / f"clip{k}.bvh")
        motions.append(bvh.load(d / f"clip{k}.bvh"))
    out = render_html(motions, d / "view.html", titles=["neutral 60 fps", "energetic 30 fps", "sad 60 fps"])
    return out, motions


@pytest.fixture(scope="module")
def browser():
    with Browser(CHROMIUM, width=WIDTH, height=HEIGHT) as b:
        yield b


def _panels(b):
    return b.evaluate("Array.from(document.querySelectorAll('.panel canvas')).map(c => {"
                      "const r = c.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; })")


def _crop(img, rect):
    x0, y0, x1, y1 = (int(round(v)) for v in rect)
    return img[max(y0, 0):min(y1, img.shape[0]), max(x0, 0):min(x1, img.shape[1])].astype(np.int32)


def _near(crop, color, tol=60):
    return int((np.abs(crop - _rgb(color)).sum(-1) < tol).sum())


def test_viewer_in_headless_chromium(page, browser):
    path, motions = page
    url = path.resolve().as_uri()
    b = browser
    b.open(url + "#t=0.5&paused=1")
    info = b.evaluate("jaxgestViewer.info()")
    # (c) the page reports each clip as the BVH file has it, and decodes the positions FK gives
    assert [c["frames"] for c in info["clips"]] == [m.num_frames for m in motions]
    assert [c["fps"] for c in info["clips"]] == [m.fps for m in motions]
    for c, m in zip(info["clips"], motions):
        assert c["duration"] == pytest.approx(m.num_frames / m.fps, abs=1e-9)
    assert info["duration"] == pytest.approx(max(m.duration for m in motions))
    assert info["time"] == pytest.approx(0.5) and not info["playing"] and info["panels"] == 3
    assert [c["frame"] for c in info["clips"]] == [30, 15, 30]  # synchronised by time, not by frame
    for k, m in enumerate(motions):
        fk = np.asarray(forward_kinematics(m)) * CM_TO_M
        for f, j in ((0, 0), (m.num_frames // 2, m.skeleton.index("Hand_L")), (m.num_frames - 1, 4)):
            got = np.array(b.evaluate(f"jaxgestViewer.position({k}, {f}, {j})"))
            assert np.abs(got - fk[f, j]).max() < 1e-4, (k, f, j, got, fk[f, j])

    b.next_frame()
    first = b.screenshot()
    rects = _panels(b)
    assert len(rects) == 3
    # (a) every panel shows a skeleton: bones in the left and the right colour
    for k, rect in enumerate(rects):
        crop = _crop(first, rect)
        assert _near(crop, COLORS["L"]) > 100 and _near(crop, COLORS["R"]) > 100, k

    # (b) another time: the picture changes inside every panel
    b.evaluate("jaxgestViewer.setTime(1.6)")
    b.next_frame()
    second = b.screenshot()
    assert b.evaluate("jaxgestViewer.info().time") == pytest.approx(1.6)
    for k, rect in enumerate(rects):
        diff = np.abs(_crop(first, rect) - _crop(second, rect)).sum(-1) > 60
        assert diff.sum() > 200, (k, int(diff.sum()))

    # the right arrow key steps one frame of the fastest clip
    b.send("Input.dispatchKeyEvent", {"type": "keyDown", "key": "ArrowRight", "code": "ArrowRight",
                                      "windowsVirtualKeyCode": 39})
    b.send("Input.dispatchKeyEvent", {"type": "keyUp", "key": "ArrowRight", "code": "ArrowRight",
                                      "windowsVirtualKeyCode": 39})
    assert b.evaluate("jaxgestViewer.info().time") == pytest.approx(1.6 + 1 / 60)

    # (d) nothing but the page itself was requested, and nothing went wrong
    requests = {u.split("#")[0] for u in b.requests()}
    assert requests <= {url}, requests
    assert b.js_errors() == []
    status = json.loads(b.evaluate("document.getElementById('jaxgest-status').textContent"))
    assert status["errors"] == [] and status["resources"] == []
    assert b.evaluate("document.documentElement.getAttribute('data-errors')") is None


def test_viewer_overlay_side_view_and_trails(page, browser):
    path, motions = page
    b = browser
    n_events = len(b.events)
    b.open(path.resolve().as_uri() + "#t=1.0&overlay=1&trails=1&trail=1.5&view=side")
    b.next_frame()
    info = b.evaluate("jaxgestViewer.info()")
    assert info["panels"] == 1 and info["overlay"]
    assert b.evaluate("jaxgestViewer.camera.yaw") == pytest.approx(np.pi / 2)
    rect, = _panels(b)
    crop = _crop(b.screenshot(), rect)
    for tint in ("#1f77b4", "#d62728", "#2ca02c"):  # each clip in its own colour
        assert _near(crop, tint) > 50, tint
    new = b.events[n_events:]
    assert not [e for e in new if e["method"] == "Runtime.exceptionThrown"]


def test_viewer_plays_to_the_end_without_loop(page, browser):
    """Playback at 2x with loop off advances and stops on the last frame (no timing is asserted)."""
    path, motions = page
    b = browser
    b.open(path.resolve().as_uri() + "#speed=2&loop=0")
    assert b.evaluate("document.getElementById('speed').value") == "2"
    done = b.evaluate("new Promise(r => { const t0 = performance.now(); (function wait() {"
                      " const i = jaxgestViewer.info();"
                      " if (!i.playing || performance.now() - t0 > 30000) r(i);"
                      " else setTimeout(wait, 50); })(); })",
                      await_promise=True)
    last = max(m.num_frames / m.fps for m in motions) - 1 / max(m.fps for m in motions)
    assert not done["playing"] and done["time"] == pytest.approx(last, abs=1e-6)
    assert [c["frame"] for c in done["clips"]] == [m.num_frames - 1 for m in motions]


# ------------------------------------------------------------------------------------------------------
# speech (issue 60): the embedded audio decodes, lasts as long as the WAV, and its clock leads the drawing

SPEECH_FPS = 30.0


@pytest.fixture(scope="module")
def speech_page(tmp_path_factory):
    """A 6 s synthetic clip at 30 fps beside the same clip at 60 fps, with its speech (WAV at 16 kHz)."""
    import soundfile as sf

    d = tmp_path_factory.mktemp("speech")
    motion, audio, sr = render_clip(CONTENTS["greeting"].with_seed(0, 6.0), "neutral", seed=0)
    sf.write(d / "speech.wav", audio, sr)
    bvh.save(resample_motion(motion, SPEECH_FPS), d / "clip30.bvh")
    bvh.save(motion, d / "clip60.bvh")
    motions = [bvh.load(d / "clip30.bvh"), bvh.load(d / "clip60.bvh")]
    out = render_html(motions, d / "speech.html", audio=d / "speech.wav")
    return out, motions, sf.info(str(d / "speech.wav")).duration


def _click(b, element_id):
    """A real mouse click (a user gesture, which lets the page start sound)."""
    x, y = b.evaluate(f"(r => [r.left + r.width / 2, r.top + r.height / 2])"
                      f"(document.getElementById('{element_id}').getBoundingClientRect())")
    for kind in ("mousePressed", "mouseReleased"):
        b.send("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": "left", "clickCount": 1})


def _wait(b, condition, what, seconds=20):
    """Poll ``condition`` (JavaScript over ``i = jaxgestViewer.info()``) until it holds; that info."""
    got = b.evaluate("new Promise(r => { const t0 = performance.now(); (function wait() {"
                     " const i = jaxgestViewer.info();"
                     f" if ({condition}) r({{ok: true, info: i}});"
                     f" else if (performance.now() - t0 > {seconds * 1000}) r({{ok: false, info: i}});"
                     " else setTimeout(wait, 20); })(); })", await_promise=True)
    assert got["ok"], (what, got["info"])
    return got["info"]


def test_speech_plays_with_the_motion(speech_page, browser):
    path, motions, wav_seconds = speech_page
    url = path.resolve().as_uri()
    b = browser
    n_events = len(b.events)
    b.open(url + "#paused=1")
    assert "media-src data:" in b.evaluate(
        "document.querySelector('meta[http-equiv=Content-Security-Policy]').content")
    assert b.evaluate("document.getElementById('jaxgest-audio').src.startsWith('data:audio/')")
    # the audio decodes, and lasts as long as the WAV (within one frame of the slowest clip)
    i = _wait(b, "i.audio.readyState >= 2", "audio decoded")
    assert i["audio"]["duration"] == pytest.approx(wav_seconds, abs=1 / SPEECH_FPS)
    assert i["audio"]["paused"] and i["clock"] == "wall" and not i["playing"]

    # play (a real click): the audio plays and its clock leads
    _click(b, "play")
    i = _wait(b, "i.clock === 'audio'", "the audio clock leads after play")
    assert i["playing"] and not i["audio"]["paused"] and not i["audio"]["blocked"]
    # advance the audio: the drawn frame follows the audio's time (not the wall clock's)
    target = 3.0 if i["time"] < 2.0 else 0.25  # far from where the wall clock would be
    b.evaluate(f"jaxgestViewer.audio.currentTime = {target}")
    i = _wait(b, f"i.audio.drawnAt !== null && i.audio.drawnAt >= {target} "
                 f"&& i.audio.drawnAt < {target + 2.5}", "a frame drawn at the advanced audio time")
    at = i["audio"]["drawnAt"]
    assert i["clock"] == "audio" and i["time"] == at
    assert [c["frame"] for c in i["clips"]] == [min(m.num_frames - 1, round(at * m.fps)) for m in motions]

    # speed drives the audio's rate; pause pauses it; scrubbing moves it
    b.evaluate("(s => { s.value = '2'; s.dispatchEvent(new Event('change')); })"
               "(document.getElementById('speed'))")
    assert b.evaluate("jaxgestViewer.audio.playbackRate") == 2
    _click(b, "play")
    i = b.evaluate("jaxgestViewer.info()")
    assert not i["playing"] and i["audio"]["paused"]
    i = b.evaluate("jaxgestViewer.setTime(1.25)")
    assert i["audio"]["currentTime"] == pytest.approx(1.25, abs=1e-3) and i["time"] == pytest.approx(1.25)

    # loop: from near the end, play wraps the motion and the audio back to the start
    last = max(m.duration for m in motions) - 1 / max(m.fps for m in motions)
    b.evaluate(f"jaxgestViewer.setTime({last - 0.3})")
    _click(b, "play")
    i = _wait(b, "i.time < 1.0 && i.playing", "looped back to the start")
    assert i["audio"]["currentTime"] < 1.5 and not i["audio"]["paused"]

    new = b.events[n_events:]  # this test's (the browser is shared)
    requests = {e["params"]["request"]["url"].split("#")[0] for e in new
                if e["method"] == "Network.requestWillBeSent"}
    assert requests <= {url, "about:blank"}, requests
    assert not [e for e in new if e["method"] == "Runtime.exceptionThrown"]
    status = json.loads(b.evaluate("document.getElementById('jaxgest-status').textContent"))
    assert status["errors"] == [] and status["resources"] == []


def test_speech_page_before_any_gesture(speech_page, browser):
    """Opened playing, the page either plays the speech at once or (autoplay refused until the user touches
    the page, as Chromium does) plays the motion on the wall clock and says how to hear the speech."""
    path, motions, _ = speech_page
    b = browser
    b.open(path.resolve().as_uri())
    i = _wait(b, "i.time > 0.2 && (i.clock === 'audio' || i.audio.blocked)", "playing")
    hint_hidden = b.evaluate("document.getElementById('soundHint').hidden")
    if i["audio"]["blocked"]:
        assert i["clock"] == "wall" and i["audio"]["paused"] and not hint_hidden
        # any key is a gesture that lets the page start sound
        b.send("Input.dispatchKeyEvent", {"type": "keyDown", "key": "o", "code": "KeyO"})
        b.send("Input.dispatchKeyEvent", {"type": "keyUp", "key": "o", "code": "KeyO"})
        i = _wait(b, "i.clock === 'audio'", "the speech joins at the first key press")
    assert not i["audio"]["blocked"] and i["playing"]
    assert b.evaluate("document.getElementById('soundHint').hidden")

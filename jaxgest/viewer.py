"""Self-contained 3D HTML viewer of motions side by side (``jaxgest render ... --out view.html``).

One HTML file holds everything: the page template, its stylesheet and a small hand-written canvas-2D
renderer (``jaxgest/assets/viewer.{html,css,js}``, inlined) and the clips' joint positions. It needs no
network (a Content-Security-Policy forbids every request) and works opened from disk.

Positions are :func:`jaxgest.motion.kinematics.forward_kinematics` of each clip, in metres (file units x
``units_to_m``; both datasets and the synthetic data are centimetres), Y up. They are stored compactly per
clip: the per-frame centroid of the joints as float32, and every joint's offset from that centroid quantised
to uint16 on a per-axis grid spanning the clip's offsets (a 2 m body gives steps of 0.03 mm), both base64.
Three 10 s clips at 30 fps of the 75-joint ZEGGS rig take about 0.55 MB. :func:`decode_clip` is the
reference of the page's decoder (same arithmetic).

Playback is by time: clips of different lengths and frame rates stay synchronised (a clip shows frame
``min(round(t * fps), frames - 1)``, holding its last frame as the GIFs do). The page sets
``data-ready="1"`` on ``<html>`` once it has drawn and exposes ``window.jaxgestViewer`` (``info()``,
``setTime(t)``, ``position(clip, frame, joint)``) and a JSON status element ``#jaxgest-status`` for tests;
URL hash parameters (``#t=1.5&paused=1&view=side&overlay=1&trails=1``) set the initial state.

Speech (``audio=``, ``jaxgest render ... --audio A.wav``) is embedded as a ``data:`` URI that an ``<audio>``
element plays; the page's policy then allows ``media-src data:`` and nothing else. See :func:`encode_audio`
for the encoding and the offset, and ``docs/cli.md`` for how the page plays it with the motion.
"""

from __future__ import annotations

import base64
import functools
import html
import importlib.resources
import json
import pathlib
import io
from typing import Optional, Sequence, Tuple, Union

import numpy as np

from jaxgest.runtime.errors import AudioError, DataError
from jaxgest.runtime.io import atomic_output, check_output_path
from jaxgest.motion.skeleton import Motion
from jaxgest.render import COLORS, _as_list, _side, _titles

#: file units -> metres (BVH files of both datasets and the synthetic data are in centimetres)
CM_TO_M = 0.01
#: the page's format version (``data.version``)
FORMAT = 1
HTML_SUFFIXES = (".html", ".htm")
#: sample rate of embedded speech (ZeroEGGS reads speech at 16 kHz too: nothing the models hear is lost)
AUDIO_RATE = 16000
#: the policy of every page: no request of any kind (scripts and styles are inline)
CSP = "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'"
#: ... and of a page with speech: media from ``data:`` URIs only
CSP_AUDIO = CSP + "; media-src data:"

AudioInput = Union[str, pathlib.Path, Tuple[np.ndarray, int]]


@functools.lru_cache(maxsize=None)
def _asset(name: str) -> str:
    return importlib.resources.files("jaxgest").joinpath("assets", name).read_text(encoding="utf-8")


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def _named(skeleton, names) -> list:
    """Indices of body joints ``names`` through the skeleton's joint map, [] when no map fits."""
    from jaxgest.motion import body

    try:
        return body.joint_indices(skeleton, names)
    except (DataError, KeyError):
        return []


def _hands(skeleton) -> list:
    from jaxgest.motion import body

    found = _named(skeleton, body.HANDS)
    if found:
        return found
    out = []  # no joint map: the shortest joint name with "hand" on each side
    for side in ("L", "R"):
        cands = [(len(n), j) for j, n in enumerate(skeleton.names)
                 if "hand" in n.lower() and _side(n) == side]
        if cands:
            out.append(min(cands)[1])
    return out


def _feet(skeleton) -> list:
    from jaxgest.motion import body

    found = _named(skeleton, body.FEET)
    if found:
        return found
    return [j for j, n in enumerate(skeleton.names) if any(k in n.lower() for k in ("foot", "toe", "ankle"))]


def world_positions(motion: Motion, units_to_m: float = CM_TO_M) -> np.ndarray:
    """(F, J, 3) joint positions in metres, Y up (forward kinematics of ``motion``)."""
    from jaxgest.motion.kinematics import forward_kinematics

    pos = np.asarray(forward_kinematics(motion), dtype=np.float64) * float(units_to_m)
    if not np.all(np.isfinite(pos)):
        raise DataError(f"{motion.name or 'motion'}: non-finite joint positions, cannot render")
    up = motion.skeleton.up_axis
    if up != 1:  # bring the up axis to Y, keeping a right-handed frame (as jaxgest.render.project)
        pos = np.roll(pos, 1 - up, axis=-1)
    return pos


def encode_clip(motion: Motion, title: str, units_to_m: float = CM_TO_M) -> dict:
    """The page's record of one clip: metadata and compactly stored positions (see the module docstring)."""
    pos = world_positions(motion, units_to_m)
    F, J, _ = pos.shape
    if F == 0:
        raise DataError(f"{motion.name or title}: a clip without frames cannot be shown")
    center = pos.mean(axis=1).astype(np.float32)  # (F, 3)
    local = pos - center.astype(np.float64)[:, None, :]
    lo = local.min(axis=(0, 1))
    span = local.max(axis=(0, 1)) - lo
    step = np.where(span > 0, span / 65535.0, 1.0)
    q = np.clip(np.rint((local - lo) / step), 0, 65535).astype("<u2")
    sk = motion.skeleton
    head = [j for j, n in enumerate(sk.names) if n.lower() == "head"]
    return {
        "title": str(title),
        "fps": float(motion.fps),
        "frames": int(F),
        "duration": float(motion.duration),
        "joints": [str(n) for n in sk.names],
        "parents": [int(p) for p in sk.parents],
        "side": "".join(_side(n) for n in sk.names),
        "head": head[0] if head else -1,
        "hands": [int(j) for j in _hands(sk)],
        "feet": [int(j) for j in _feet(sk)],
        "center": _b64(center.astype("<f4")),
        "lo": [float(v) for v in lo],
        "step": [float(v) for v in step],
        "q": _b64(q),
    }


def decode_clip(record: dict) -> np.ndarray:
    """(F, J, 3) positions in metres from an :func:`encode_clip` record (the page's decoder, in NumPy)."""
    F, J = record["frames"], len(record["joints"])
    center = np.frombuffer(base64.b64decode(record["center"]), dtype="<f4").reshape(F, 3).astype(np.float64)
    q = np.frombuffer(base64.b64decode(record["q"]), dtype="<u2").reshape(F, J, 3).astype(np.float64)
    return center[:, None, :] + np.asarray(record["lo"]) + q * np.asarray(record["step"])


def _opus_available() -> bool:
    import soundfile as sf

    return "OPUS" in sf.available_subtypes("OGG")


def encode_audio(audio: AudioInput, duration: float, offset: float = 0.0) -> dict:
    """The page's record of the speech heard with the motion: ``duration`` seconds of ``audio`` from
    ``offset`` seconds into it, as a ``data:`` URI.

    The window: the page's time t (the motion's, from 0 to ``duration``, the longest clip) plays the speech at
    ``t + offset``; a positive ``offset`` skips the speech's first seconds, a negative one starts it later
    (silence before it), and speech shorter than the window is followed by silence. The embedded audio thus
    lasts exactly ``duration`` and its clock is the page's clock: the drawn frame is
    ``round(audio.currentTime * fps)`` (= the source's time minus ``offset``, times fps).

    The encoding: mono, resampled to 16 kHz (:data:`AUDIO_RATE`), Ogg Opus written by libsndfile through
    soundfile (already a dependency; its wheels carry a libsndfile with Opus): about 3.5 kB per second of
    speech (28 kbit/s; 4.7 kB as base64), a tenth of 16-bit PCM WAV, and Chromium and Firefox play it (the
    browser test checks Chromium's duration within a frame). Where the installed libsndfile has no Opus
    encoder, 16-bit PCM WAV at 16 kHz (32 kB/s, played everywhere) instead. ``codec`` in the record says which.

    Args:
      audio: a sound file (WAV, FLAC, ...; any rate and channel count) or ``(samples, sample_rate)``.
      duration: seconds of the window (> 0).
      offset: seconds into the speech at the motion's first frame.
    Raises:
      AudioError: the file is missing, unreadable, empty or not finite.
      DataError: the window misses the speech entirely.
    """
    import soundfile as sf

    from jaxgest.audio import load_audio

    if isinstance(audio, (str, pathlib.Path)):
        y, _ = load_audio(audio, sr=AUDIO_RATE)
        source, label = pathlib.Path(audio).name, str(audio)
    else:
        samples, sr = audio
        y = np.asarray(samples, np.float32)
        if y.ndim == 2:
            y = y.mean(axis=1)
        if y.ndim != 1 or y.size == 0 or not np.all(np.isfinite(y)):
            raise AudioError("speech for the viewer: expected finite mono or (samples, channels) audio")
        if int(sr) != AUDIO_RATE:
            import librosa

            y = librosa.resample(y, orig_sr=int(sr), target_sr=AUDIO_RATE).astype(np.float32)
        source, label = None, "speech"
    offset = float(offset)
    if not np.isfinite(offset):
        raise DataError(f"--audio-offset must be a finite number of seconds, got {offset}")
    n = int(round(float(duration) * AUDIO_RATE))
    start = int(round(offset * AUDIO_RATE))
    speech_s = y.size / AUDIO_RATE
    if n <= 0 or start >= y.size or start + n <= 0:
        raise DataError(f"{label}: an offset of {offset:g} s puts the speech ({speech_s:.3f} s) "
                        f"outside the motion (0 to {float(duration):.3f} s)")
    window = np.zeros(n, np.float32)
    lo, hi = max(start, 0), min(start + n, y.size)
    window[lo - start:hi - start] = y[lo:hi]
    window = np.clip(window, -1.0, 1.0)
    buf = io.BytesIO()
    if _opus_available():
        sf.write(buf, window, AUDIO_RATE, format="OGG", subtype="OPUS")
        codec, mime = "opus", "audio/ogg"
    else:
        sf.write(buf, window, AUDIO_RATE, format="WAV", subtype="PCM_16")
        codec, mime = "pcm16", "audio/wav"
    raw = buf.getvalue()
    return {
        "src": f"data:{mime};base64," + base64.b64encode(raw).decode("ascii"),
        "codec": codec,
        "sampleRate": AUDIO_RATE,
        "duration": n / AUDIO_RATE,
        "offset": offset,
        "source": source,
        "speechSeconds": speech_s,
        "bytes": len(raw),
    }


def decode_audio(record: dict) -> np.ndarray:
    """The samples of an :func:`encode_audio` record (mono float32 at ``record["sampleRate"]``)."""
    import soundfile as sf

    _, _, b64 = record["src"].partition(";base64,")
    y, sr = sf.read(io.BytesIO(base64.b64decode(b64)), dtype="float32")
    if sr != record["sampleRate"]:
        raise ValueError(f"decode_audio: {sr} Hz, the record says {record['sampleRate']}")
    return y


def page_data(motions, titles=None, *, overlay: bool = False, trails: bool = False,
              trail_seconds: float = 1.0, units_to_m: float = CM_TO_M, heading: Optional[str] = None,
              audio: Optional[AudioInput] = None, audio_offset: float = 0.0) -> dict:
    """The JSON the page reads: clips (:func:`encode_clip`), colours, initial options and the speech
    (:func:`encode_audio`, ``None`` without ``audio``)."""
    motions = _as_list(motions)
    titles = _titles(titles, len(motions)) or [m.name or f"clip {k + 1}" for k, m in enumerate(motions)]
    if not trail_seconds > 0:
        raise DataError(f"viewer: the hand-trajectory window must be positive, got {trail_seconds} s")
    clips = [encode_clip(m, t, units_to_m) for m, t in zip(motions, titles)]
    speech = None
    if audio is not None:
        speech = encode_audio(audio, max(c["duration"] for c in clips), audio_offset)
    return {
        "version": FORMAT,
        "heading": heading,
        "units": "m",
        "colors": COLORS,
        "options": {"overlay": bool(overlay), "trails": bool(trails), "trailSeconds": float(trail_seconds)},
        "clips": clips,
        "audio": speech,
    }


def _json_for_script(obj) -> str:
    """JSON safe inside ``<script type="application/json">`` (no ``</script>``, no ``<!--``)."""
    return json.dumps(obj, separators=(",", ":")).replace("<", "\\u003c").replace(">", "\\u003e")


def html_page(motions, titles=None, **kw) -> str:
    """The whole self-contained HTML page as a string (see :func:`page_data` for the options)."""
    data = page_data(motions, titles, **kw)
    heading = data["heading"] or " | ".join(c["title"] for c in data["clips"])
    page = _asset("viewer.html")
    csp = CSP_AUDIO if data["audio"] else CSP
    slots = (("{{CSP}}", csp), ("{{TITLE}}", html.escape(heading)), ("{{CSS}}", _asset("viewer.css")),
             ("{{DATA}}", _json_for_script(data)), ("{{JS}}", _asset("viewer.js")))
    for key, value in slots:
        if key not in page:
            raise RuntimeError(f"viewer.html: template has no {key}")
        page = page.replace(key, value, 1)
    return page


def render_html(
    motions: Union[Motion, Sequence[Motion]],
    out_path,
    titles: Optional[Sequence[str]] = None,
    *,
    overlay: bool = False,
    trails: bool = False,
    trail_seconds: float = 1.0,
    heading: Optional[str] = None,
    audio: Optional[AudioInput] = None,
    audio_offset: float = 0.0,
) -> pathlib.Path:
    """Write a self-contained 3D viewer page of one motion or several side by side (or ``overlay``).

    Args:
      motions: a Motion or a list of Motions (one panel each).
      out_path: the .html to write (atomically, :func:`jaxgest.io.atomic_output`).
      titles: one title per panel (default: the motions' names).
      overlay: start with all clips drawn in one panel (the page can switch).
      trails: start with hand trajectories shown over the last ``trail_seconds`` (the page can switch).
      heading: the page's title (default: the panel titles joined).
      audio: speech to play with the motion, a sound file or ``(samples, sample_rate)``
        (:func:`encode_audio`); its clock then leads the playback.
      audio_offset: seconds into ``audio`` at the motion's first frame.
    Raises:
      DataError: the output directory does not exist, titles do not match, or positions are not finite.
      AudioError: ``audio`` is missing, unreadable, empty or not finite.
    """
    out = check_output_path(out_path)
    text = html_page(motions, titles, overlay=overlay, trails=trails, trail_seconds=trail_seconds,
                     heading=heading, audio=audio, audio_offset=audio_offset)
    with atomic_output(out) as tmp:
        pathlib.Path(tmp).write_text(text, encoding="utf-8")
    return out


# ------------------------------------------------------------------------------------------------------
# pages of evaluation cases (``jaxgest tgst evaluate --html DIR``, ``jaxgest zeggs evaluate --html DIR``)

CASES = ("best", "median", "worst")


def best_median_worst(items: Sequence, scores: Sequence[float]) -> list:
    """``[("best", item), ("median", item), ("worst", item)]``: the items of the lowest, the median (lower
    median) and the highest score (lower is better). Fewer distinct items give fewer cases."""
    if len(items) != len(scores):
        raise ValueError("best_median_worst: one score per item")
    if not items:
        return []
    order = [int(i) for i in np.argsort(np.asarray(scores, np.float64), kind="stable")]
    picks = [order[0], order[(len(order) - 1) // 2], order[-1]]
    out, seen = [], set()
    for label, i in zip(CASES, picks):
        if i not in seen:
            seen.add(i)
            out.append((label, items[i]))
    return out


def prepare_html_dir(path) -> pathlib.Path:
    """The ``--html DIR`` folder, created when its parent exists (checked before any long computation)."""
    d = pathlib.Path(path)
    if d.exists() and not d.is_dir():
        raise DataError(f"{d}: --html needs a folder, and this is a file")
    if not d.parent.is_dir():
        raise DataError(f"{d}: --html folder's parent {d.parent} does not exist")
    d.mkdir(exist_ok=True)
    return d


def tgst_evaluation_pages(report: dict, model, clips, out_dir) -> list:
    """Viewer pages of the best, median and worst pairs of a ``jaxgest tgst evaluate`` report.

    A pair's score is the first evaluated method's content error plus its style error, each divided by its
    median over the evaluated pairs (the two are in different units). Each page shows content | style |
    every method's result (transferred again with ``model``; titles carry the report's errors) | ground
    truth. ``clips``: the dataset's clips (:func:`jaxgest.motion.datasets.load_folder`), matched by path.
    """
    out_dir = pathlib.Path(out_dir)
    methods = list(report["methods"])
    first = methods[0]
    rows = [r for r in report["per_pair"] if "content" in r["errors"].get(first, {})]
    if not rows:
        raise DataError(f"--html: no evaluated pair (every {first} transfer was skipped)")
    ce = np.array([r["errors"][first]["content"]["mean"] for r in rows])
    se = np.array([r["errors"][first]["style"]["mean"] for r in rows])
    score = ce / max(float(np.median(ce)), 1e-12) + se / max(float(np.median(se)), 1e-12)
    by_path = {str(c.path): c for c in clips}
    written = []
    for label, rec in best_median_worst(rows, list(score)):
        content, style = by_path[rec["content"]].motion, by_path[rec["style"]].motion
        panels, titles = [content, style], ["content", f"style ({rec['style_label']})"]
        for m in methods:
            e = rec["errors"].get(m, {})
            panels.append(model.transfer(content, style, method=m))
            titles.append(f"{m}: {e['content']['mean']:.3f} m, {e['style']['mean']:.3f} m/s" if "content" in e
                          else f"{m} (skipped)")
        if rec.get("ground_truth"):
            panels.append(by_path[rec["ground_truth"]].motion)
            titles.append("ground truth")
        heading = (f"{label} pair ({first}): {pathlib.Path(rec['content']).stem} in the style of "
                   f"{pathlib.Path(rec['style']).stem}")
        written.append(render_html(panels, out_dir / f"{label}.html", titles=titles, heading=heading))
    return written


def zeggs_evaluation_pages(result: dict, model, clips, out_dir, *, seed: int = 0) -> list:
    """Viewer pages of the best, median and worst test clips of a ``jaxgest zeggs evaluate`` result, ranked
    by the generated motion's BeatAlign minus its shuffled control (higher is better). Each page shows the
    motion generated from the clip's audio with its style example (generated again with ``model`` and the
    evaluation's seed) | the real clip | the style example, with the hand trajectories on, and plays the
    clip's speech (the generated and the real motion are in step with it; the style example is not)."""
    from jaxgest.motion.datasets import load_clip_audio

    out_dir = pathlib.Path(out_dir)
    rows = result.get("beat_alignment", {}).get("per_clip") or []
    if not rows:
        raise DataError("--html: no generated test clip to show (generation skipped or no clip scored)")
    by_path = {str(c.path): c for c in clips}
    gain = [r["generated"]["aligned"] - r["generated"]["shuffled"] for r in rows]
    written = []
    for label, rec in best_median_worst(rows, [-g for g in gain]):
        clip, example = by_path[rec["clip"]], by_path[rec["style_example"]]
        audio, sr = load_clip_audio(clip)
        gen = model.generate(audio, [example.motion], sr=sr, seed=seed, name=f"{clip.path.stem}_gen")
        g, r = rec["generated"], rec["real"]
        titles = [f"generated: BeatAlign {g['aligned']:.3f} (shuffled {g['shuffled']:.3f})",
                  f"real: {r['aligned']:.3f} (shuffled {r['shuffled']:.3f})",
                  f"style example ({example.style})"]
        heading = f"{label} clip: {clip.path.stem} ({clip.style})"
        written.append(render_html([gen, clip.motion, example.motion], out_dir / f"{label}.html",
                                   titles=titles, heading=heading, trails=True, audio=(audio, sr)))
    return written

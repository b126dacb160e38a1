"""Contents of the built-in synthetic data: seeded stroke scripts timed to a speech-like signal.

A content is a :class:`ContentSpec` (name, length, seed, stroke vocabulary, syllable rate, pitch). Its
:func:`make_script` draws phrases of syllables (voiced bursts at the syllable rate, separated by pauses),
marks stressed syllables, and places gesture strokes whose apexes fall exactly on stressed-syllable
onsets. :func:`speech_audio` turns the same syllables into audio: a harmonic tone with a declining,
stress-raised pitch contour, fricative noise bursts and a sharp-attack syllable envelope, so an onset
detector finds the syllable onsets. Everything depends only on the spec (never on the style), so one
content rendered in several styles shares its audio and its stroke timing.

| content     | syllable rate Hz | f0 Hz | stroke vocabulary (weights)                          |
|-------------|------------------|-------|------------------------------------------------------|
| greeting    | 4.5              | 190   | wave 3, bow 2, arms-open 1, beat 1                   |
| directions  | 4.0              | 150   | point 4, beat 2, raise 1                             |
| argument    | 5.5              | 130   | beat 5, point 2, arms-open 1                         |
| celebration | 5.0              | 220   | raise 3, arms-open 3, wave 1, beat 1                 |
| apology     | 3.2              | 170   | bow 3, beat 1, arms-open 1                           |
| story       | 4.2              | 160   | beat 1, point 1, wave 1, raise 1, bow 1, arms-open 1 |
"""

from __future__ import annotations

import dataclasses
import zlib

import numpy as np

STROKE_TYPES = ("beat", "point", "wave", "raise", "bow", "arms-open")
# Probability that a stroke of this type uses both hands (otherwise the dominant hand).
BOTH_HANDS = {"beat": 0.3, "point": 0.0, "wave": 0.0, "raise": 0.6, "bow": 1.0, "arms-open": 1.0}
# Minimum time (s, at tempo 1) after a stroke's apex before the next apex.
MIN_GAP = {"beat": 0.9, "point": 1.3, "wave": 2.0, "raise": 1.6, "bow": 2.0, "arms-open": 1.5}


@dataclasses.dataclass(frozen=True)
class ContentSpec:
    """A named content: what is said and gestured (independent of style)."""

    name: str
    seconds: float = 10.0  # clip length
    seed: int = 0  # script + audio seed
    strokes: tuple = ()  # ((stroke type, weight), ...)
    syllable_rate: float = 4.5  # Hz
    f0: float = 160.0  # Hz, phrase-initial pitch

    def with_seed(self, seed: int, seconds: float | None = None) -> "ContentSpec":
        """The same content with a script seed derived from ``seed`` (and optionally another length)."""
        base = zlib.crc32(self.name.encode()) % 100_000
        return dataclasses.replace(
            self, seed=base + 100_003 * int(seed), seconds=self.seconds if seconds is None else float(seconds)
        )


def _spec(name, rate, f0, **weights):
    strokes = tuple((k.replace("_", "-"), float(v)) for k, v in weights.items())
    return ContentSpec(name, strokes=strokes, syllable_rate=rate, f0=f0).with_seed(0)


CONTENTS: dict = {
    c.name: c
    for c in (
        _spec("greeting", 4.5, 190.0, wave=3, bow=2, arms_open=1, beat=1),
        _spec("directions", 4.0, 150.0, point=4, beat=2, **{"raise": 1}),
        _spec("argument", 5.5, 130.0, beat=5, point=2, arms_open=1),
        _spec("celebration", 5.0, 220.0, **{"raise": 3}, arms_open=3, wave=1, beat=1),
        _spec("apology", 3.2, 170.0, bow=3, beat=1, arms_open=1),
        _spec("story", 4.2, 160.0, beat=1, point=1, wave=1, **{"raise": 1}, bow=1, arms_open=1),
    )
}


@dataclasses.dataclass(frozen=True)
class Stroke:
    kind: str  # one of STROKE_TYPES
    apex: float  # s, equals a stressed-syllable onset
    hands: str  # "dominant" | "both"
    intensity: float  # 0.8 .. 1.2, scales the displacement


@dataclasses.dataclass(frozen=True)
class Script:
    spec: ContentSpec
    onsets: np.ndarray  # (S,) syllable onset times, s
    durations: np.ndarray  # (S,) voiced durations, s
    stress: np.ndarray  # (S,) bool
    strokes: tuple  # Stroke, sorted by apex


def get_content(content) -> ContentSpec:
    if isinstance(content, ContentSpec):
        return content
    try:
        return CONTENTS[content]
    except KeyError:
        raise KeyError(f"unknown synthetic content {content!r}; known: {', '.join(CONTENTS)}") from None


def make_script(spec: ContentSpec) -> Script:
    """Syllables (phrases with pauses) and strokes on stressed onsets, deterministic in ``spec.seed``."""
    rng = np.random.default_rng(spec.seed)
    onsets, durs, stress = [], [], []
    t = 1.0 + rng.uniform(0.0, 0.3)
    end = spec.seconds - 0.8
    while t < end:
        phrase_end = min(t + rng.uniform(1.6, 3.2), end)
        first = True
        while t < phrase_end:
            step = rng.uniform(0.75, 1.25) / spec.syllable_rate
            onsets.append(t)
            durs.append(0.7 * step)
            stress.append(first or rng.random() < 0.35)
            first = False
            t += step
        t += rng.uniform(0.35, 0.8)
    onsets, durs, stress = np.array(onsets), np.array(durs), np.array(stress, dtype=bool)
    kinds = [k for k, _ in spec.strokes] or list(STROKE_TYPES)
    w = np.array([w for _, w in spec.strokes] or [1.0] * len(kinds))
    w = w / w.sum()
    strokes = []
    next_ok = 0.0
    for t0 in onsets[stress]:
        if t0 < next_ok or t0 > spec.seconds - 1.2:
            continue
        kind = kinds[rng.choice(len(kinds), p=w)]
        hands = "both" if rng.random() < BOTH_HANDS[kind] else "dominant"
        strokes.append(Stroke(kind, float(t0), hands, float(rng.uniform(0.8, 1.2))))
        next_ok = t0 + MIN_GAP[kind]
    return Script(spec, onsets, durs, stress, tuple(strokes))


def speech_audio(script: Script, sr: int = 16000) -> np.ndarray:
    """Speech-like mono audio (samples,) float32 in [-1, 1] for ``script``, deterministic in its seed.

    Voiced bursts: harmonics 1..12 (1/k roll-off, per-syllable formant tilt) of a pitch contour that
    declines over each phrase and rises on stressed syllables; a 12 ms linear attack and a power decay
    per syllable; a fricative noise burst at some syllable starts; a faint noise floor in pauses.
    """
    spec = script.spec
    rng = np.random.default_rng(spec.seed + 7)
    n = int(round(spec.seconds * sr))
    tt = np.arange(n) / sr
    f0 = np.full(n, spec.f0 * 0.9)
    amp = np.zeros(n)
    tilt = np.zeros(n)
    noise_env = np.zeros(n)
    # phrase position for declination: distance since the last long gap
    phrase_start = script.onsets[0] if len(script.onsets) else 0.0
    prev_end = -1.0
    for on, d, st in zip(script.onsets, script.durations, script.stress):
        if on - prev_end > 0.3:
            phrase_start = on
        prev_end = on + d
        a, b = int(on * sr), min(int((on + d) * sr), n)
        if b <= a:
            continue
        local = (tt[a:b] - on) / d
        att = 0.012 / d
        env = np.where(local < att, local / att, (1 - (local - att) / (1 - att)) ** 1.5)
        amp[a:b] = np.maximum(amp[a:b], env * (1.0 if st else rng.uniform(0.3, 0.5)))
        decl = 1.0 - 0.15 * min((on - phrase_start) / 3.0, 1.0)
        f0[a:b] = spec.f0 * decl * (1.12 if st else 1.0) * (1 + 0.03 * np.sin(2 * np.pi * 5 * local))
        tilt[a:b] = rng.uniform(0.6, 1.4)
        if rng.random() < 0.4:
            m = min(a + int(0.03 * sr), n)
            noise_env[a:m] = np.linspace(0.25, 0.0, m - a) * (1.0 if st else 0.5)
    phase = 2 * np.pi * np.cumsum(f0) / sr
    voiced = np.zeros(n)
    for k in range(1, 13):
        voiced += np.sin(k * phase) / k ** (1.0 + 0.5 * tilt)
    white = rng.standard_normal(n)
    fric = np.diff(white, prepend=0.0) * noise_env
    y = voiced * amp + fric + 0.002 * white
    y = y / max(np.abs(y).max(), 1e-9) * 0.9
    return y.astype(np.float32)

"""Rendering one synthetic clip: a content's script performed in a style (see :mod:`jaxgest.motion.synthetic`)."""

from __future__ import annotations

import functools

import numpy as np

from jaxgest.motion.skeleton import Motion
from jaxgest.motion.synthetic.content import (
    get_content,
    make_script,
    speech_audio,
)
from jaxgest.motion.synthetic.pose import PoseTracks, make_rig, pose_to_motion_arrays
from jaxgest.motion.synthetic.strokes import stroke_tracks
from jaxgest.motion.synthetic.styles import StyleParams, get_style

FPS = 60.0
SAMPLE_RATE = 16000



@functools.lru_cache(maxsize=4)
def _rig(skeleton=None):
    if skeleton is None:
        from jaxgest.motion.body import body_skeleton

        skeleton = body_skeleton()
    return make_rig(skeleton)


def smooth(x: np.ndarray, sigma_s: float, fps: float) -> np.ndarray:
    """Zero-phase Gaussian low-pass along axis 0 (edge-padded), sigma in seconds; keeps apex timing."""
    sigma = sigma_s * fps
    if sigma < 0.5:
        return x
    r = int(np.ceil(3 * sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    pad = np.concatenate([np.repeat(x[:1], r, 0), x, np.repeat(x[-1:], r, 0)], axis=0)
    flat = pad.reshape(pad.shape[0], -1)
    out = np.stack([np.convolve(flat[:, c], k, mode="valid") for c in range(flat.shape[1])], axis=1)
    return out.reshape(x.shape)


def _slow_noise(rng, t, freqs, amp):
    """Sum of sinusoids with random phases: smooth pseudo-random drift (F,)."""
    return sum(amp * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in freqs) / len(freqs)


def idle_tracks(t, style: StyleParams, rng) -> dict:
    """Breathing, weight shift and head drift, scaled by ``style.sway`` (deterministic in ``rng``)."""
    s = style.sway
    breath_hz = 0.25 * np.sqrt(style.tempo)
    breath = np.sin(2 * np.pi * breath_hz * t + rng.uniform(0, 2 * np.pi))
    shift = _slow_noise(rng, t, (0.09, 0.17, 0.23), 2.5)
    return {
        "breath": 1.2 * s * breath,  # degrees of chest pitch (negative = chest up)
        "hips_x": s * 3.0 * shift,  # cm, weight shift over the feet
        "hips_roll": -s * 1.5 * shift,  # degrees, pelvis drops towards the unloaded side
        "hips_dip": s * 0.8 * (1 + np.abs(shift)),  # cm, slight knee bend while shifting
        "yaw": s * _slow_noise(rng, t, (0.05, 0.11), 4.0),
        "head_yaw": s * _slow_noise(rng, t, (0.07, 0.19), 6.0),
        "head_pitch": s * _slow_noise(rng, t, (0.13, 0.29), 3.0),
        "hand": {side: s * np.stack([_slow_noise(rng, t, (0.1, 0.27), 1.5) for _ in range(3)], -1)
                 for side in ("L", "R")},
    }


def tremor_noise(t, amplitude, rng) -> np.ndarray:
    """Band-limited 8-12 Hz jitter (F, 3) of roughly ``amplitude`` cm: four random sinusoids."""
    out = np.zeros((len(t), 3))
    for _ in range(4):
        d = rng.standard_normal(3)
        d /= np.linalg.norm(d)
        out += np.sin(2 * np.pi * rng.uniform(8, 12) * t + rng.uniform(0, 2 * np.pi))[:, None] * d
    return amplitude * out / 2.0


def render_clip(content, style, seed: int = 0, *, fps: float = FPS, sr: int = SAMPLE_RATE, skeleton=None):
    """Render one content in one style.

    Args:
      content: a name in :data:`CONTENTS` or a :class:`ContentSpec` (its seed fixes the script + audio).
      style: a name in :data:`STYLES` or a :class:`StyleParams`.
      seed: performance seed (idle motion phases, tremor); the script does not depend on it.
      fps: motion frame rate; sr: audio sample rate.
      skeleton: the body skeleton (default :func:`jaxgest.motion.body.body_skeleton`).
    Returns:
      ``(motion, audio, sr)``: a :class:`Motion` of ``round(seconds * fps)`` frames, float32 audio
      ``(samples,)`` and its rate.
    """
    spec = get_content(content)
    st = get_style(style)
    rig = _rig(skeleton)
    script = make_script(spec)
    audio = speech_audio(script, sr)
    F = int(round(spec.seconds * fps))
    t = np.arange(F) / fps
    rng = np.random.default_rng([int(seed), spec.seed, zlib_style(st.name)])
    tr = stroke_tracks(script, st, t)
    idle = idle_tracks(t, st, rng)
    hands = {}
    for side in ("L", "R"):
        h = smooth(tr["hand"][side] + idle["hand"][side], st.smoothness, fps)
        hands[side] = h + tremor_noise(t, st.tremor, rng) * tr["activity"][side][:, None] ** 0.5
    pitch = smooth(tr["torso_pitch"], st.smoothness, fps)
    head = smooth(tr["head_pitch"], st.smoothness, fps)
    zeros = np.zeros(F)
    lean = st.lean + pitch
    torso = {
        "Hips": np.stack([idle["yaw"], 0.35 * lean, idle["hips_roll"]], -1),
        "Spine": np.stack([idle["yaw"] * 1.2, 0.7 * lean, idle["hips_roll"] * 0.3], -1),
        "Chest": np.stack([idle["yaw"] * 1.4, lean - idle["breath"], zeros], -1),
        "Neck": np.stack([idle["yaw"] * 1.4 + 0.5 * idle["head_yaw"], lean + 0.4 * (st.head_pitch + head), zeros], -1),
        "Head": np.stack([idle["yaw"] * 1.4 + idle["head_yaw"],
                          0.5 * lean + st.head_pitch + head + idle["head_pitch"], zeros], -1),
    }
    tracks = PoseTracks(
        hand=hands,
        torso=torso,
        shrug={s: smooth(tr["shrug"][s], st.smoothness, fps) + 0.5 * idle["breath"] for s in ("L", "R")},
        hips_offset=np.stack([idle["hips_x"], -idle["hips_dip"], zeros], -1),
        wrist={s: 0.5 * np.clip((hands[s][:, 1] + 20.0) / 40.0, 0.0, 1.0) for s in ("L", "R")},
    )
    quats, trans = pose_to_motion_arrays(rig, tracks)
    motion = Motion(rig.skeleton, quats, trans, fps, name=f"{spec.name}_{st.name}_{seed}")
    return motion, audio, sr


def zlib_style(name: str) -> int:
    import zlib

    return zlib.crc32(name.encode()) % 100_000

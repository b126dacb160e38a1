"""Gesture strokes as keyframed hand / torso poses, and their timelines under a style.

Hand targets are (out, up, forward) in cm relative to the upper-arm joint, in the body's yaw frame, so
"out" is away from the body's midline for either hand. A stroke is a few keys at times relative to its
apex (seconds at tempo 1): preparation, apex (on the audio onset), hold; then a retraction to the rest
pose unless the next stroke follows too closely. The hand comes to a full stop only at an apex and at rest
(*stop* keys); the preparation and hold keys are *via* points the hand passes through without stopping.
Between two stop keys the motion is one minimum-jerk time course (References: Flash & Hogan 1985) along the
path through the via keys (hand keys along arcs around the shoulder; each key segment gets its share of the
movement's time), so the hand decelerates into every apex, on the stressed syllable, as in the
gesture-speech synchrony of beat gestures (McNeill 1992; Pouw et al. 2020); no other stop follows until
rest. During the hold the hand stays at (raise, bow, wave) or drifts slightly from (beat, point, arms-open)
the apex, then moves into the retraction without stopping; the speed rises there within a frame in the
keyframe tracks, which the style's low-pass filter smooths (hand accelerations stay within those of the
all-stops design). A stroke's speed minimum therefore lies in the apex-to-hold plateau, 0.1-0.2 s after the
apex once smoothed. Then the style's low-pass filter and tremor are applied. Before a stroke that starts from rest, the hand leaves
the rest pose ``LEAVE`` s (at tempo 1) before its preparation key.

| stroke    | prep (t, target)      | apex target    | hold (t, target)     | torso pitch / head at apex | extra                   |
|-----------|-----------------------|----------------|----------------------|----------------------------|-------------------------|
| beat      | -0.30 (14, -18, 26)   | (13, -30, 28)  | +0.18 (13, -27, 27)  | +2 / +5                    |                         |
| point     | -0.45 (18, -20, 25)   | (22, 2, 40)    | +0.45 (22, 3, 40)    | +3 / 0                     |                         |
| wave      | -0.50 (22, 0, 12)     | (26, 16, 12)   | +1.00 (26, 16, 12)   | 0 / -3                     | lateral 9 cm at 2.2 Hz  |
| raise     | -0.50 (14, 5, 15)     | (10, 40, 8)    | +0.50 (10, 40, 8)    | -4 / -6                    |                         |
| bow       | -0.60 (6, -44, 8)     | (4, -44, 10)   | +0.40 (4, -44, 10)   | +35 / +15                  | prep pitch +10          |
| arms-open | -0.45 (18, -20, 24)   | (40, -12, 22)  | +0.35 (42, -10, 20)  | -3 / -4                    | shrug 6 deg             |

Rest hand target: (7, -44, 5); retraction takes 0.55 s at tempo 1.
"""

from __future__ import annotations

import numpy as np

REST_HAND = np.array([7.0, -44.0, 5.0])
RETRACT = 0.55
LEAVE = 0.30
STOP, VIA, APEX = "stop", "via", "apex"  # key kinds; an apex is a stop that is never dropped

# kind -> list of (t, hand target, torso pitch, head pitch, shrug); the key with t == 0 is the apex
KEYS = {
    "beat": [(-0.30, (14, -18, 26), 0, 0, 0), (0.0, (13, -30, 28), 2, 5, 0), (0.18, (13, -27, 27), 1, 2, 0)],
    "point": [(-0.45, (18, -20, 25), 1, 0, 0), (0.0, (22, 2, 40), 3, 0, 2), (0.45, (22, 3, 40), 3, 0, 2)],
    "wave": [(-0.50, (22, 0, 12), 0, 0, 2), (0.0, (26, 16, 12), 0, -3, 4), (1.00, (26, 16, 12), 0, -3, 4)],
    "raise": [(-0.50, (14, 5, 15), -1, 0, 3), (0.0, (10, 40, 8), -4, -6, 8), (0.50, (10, 40, 8), -4, -6, 8)],
    "bow": [(-0.60, (6, -44, 8), 10, 5, 0), (0.0, (4, -44, 10), 35, 15, 0), (0.40, (4, -44, 10), 35, 15, 0)],
    "arms-open": [
        (-0.45, (18, -20, 24), 0, 0, 0),
        (0.0, (40, -12, 22), -3, -4, 6),
        (0.35, (42, -10, 20), -3, -4, 6),
    ],
}
WAVE_AMP, WAVE_HZ = 9.0, 2.2


def min_jerk(tau):
    """Minimum-jerk blend 10τ³ − 15τ⁴ + 6τ⁵ on [0, 1]. References: Flash & Hogan 1985."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10 - 15 * tau + 6 * tau * tau)


def _stop_warp(times, stops, t):
    """Key segment ``(k, k1)`` (F,), (F,) and linear weight ``w`` (F, 1) at frame times ``t`` after the time warp.

    Between consecutive stop keys a and b the frame time is mapped to the virtual time
    ``T_a + min_jerk((t - T_a) / (T_b - T_a)) (T_b - T_a)`` and the keys are joined linearly in virtual
    time: a single minimum-jerk movement through the via keys, with zero velocity only at the stops. With
    every key a stop this is plain piecewise minimum-jerk interpolation. The first and last keys are stops.
    """
    times = np.asarray(times, dtype=np.float64)
    stops = np.asarray(stops, dtype=bool).copy()
    stops[0] = stops[-1] = True
    st = times[stops]
    a = np.clip(np.searchsorted(st, t, side="right") - 1, 0, len(st) - 1)
    b = np.minimum(a + 1, len(st) - 1)
    span = np.maximum(st[b] - st[a], 1e-9)
    tv = np.where(b > a, st[a] + min_jerk((t - st[a]) / span) * span, st[a])
    k = np.clip(np.searchsorted(times, tv, side="right") - 1, 0, len(times) - 1)
    k1 = np.minimum(k + 1, len(times) - 1)
    w = np.where(k1 > k, np.clip((tv - times[k]) / np.maximum(times[k1] - times[k], 1e-9), 0.0, 1.0), 0.0)
    return k, k1, w[:, None]


def interpolate_keys(times, values, t, stops=None):
    """Keys (K,), (K, C) at frame times t (F,) -> (F, C): one minimum-jerk movement between consecutive
    stop keys (``stops`` (K,) bool; default every key) through the via keys in between."""
    values = np.asarray(values, dtype=np.float64)
    k, k1, w = _stop_warp(times, np.ones(len(values), bool) if stops is None else stops, t)
    return values[k] * (1 - w) + values[k1] * w


def interpolate_hand_keys(times, values, t, stops=None, min_radius: float = 20.0):
    """Like :func:`interpolate_keys` for hand targets relative to the shoulder, but along arcs: the
    direction is slerped and the distance interpolated, so a hand moving from above the head to the hip
    swings around the shoulder instead of folding the arm through it."""
    values = np.asarray(values, dtype=np.float64)
    k, k1, w = _stop_warp(times, np.ones(len(values), bool) if stops is None else stops, t)
    a, b = values[k], values[k1]
    ra, rb = np.linalg.norm(a, axis=-1, keepdims=True), np.linalg.norm(b, axis=-1, keepdims=True)
    ua, ub = a / np.maximum(ra, 1e-9), b / np.maximum(rb, 1e-9)
    theta = np.arccos(np.clip(np.sum(ua * ub, axis=-1, keepdims=True), -1.0, 1.0))
    small = theta < 1e-4
    sin_t = np.where(small, 1.0, np.sin(theta))
    wa = np.where(small, 1 - w, np.sin((1 - w) * theta) / sin_t)
    wb = np.where(small, w, np.sin(w * theta) / sin_t)
    u = wa * ua + wb * ub
    u /= np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-9)
    return u * np.maximum(ra * (1 - w) + rb * w, min_radius)


def leave_lead(tempo: float) -> float:
    """Seconds between leaving the rest pose and a stroke's first key: ``LEAVE / tempo``, but more than the
    0.08 s within which :func:`_add_keys` merges keys, so very fast tempi keep the preparation key."""
    return max(LEAVE / tempo, 0.12)


def _add_keys(keys, new, kinds, rest, lead):
    """Append one stroke's keys ``(t, value)`` of ``kinds`` to a timeline of ``(t, value, kind)``, trimming
    what overlaps; apex keys are never dropped. When the timeline ends at rest (a stop) well before the
    stroke, the hand stays there until ``lead`` s before the first key (a stop at ``rest``)."""
    t_first = new[0][0]
    while len(keys) > 1 and keys[-1][0] > t_first - 0.08 and keys[-1][2] != APEX:  # keys[0]: the start pose
        keys.pop()
    if keys and keys[-1][2] == STOP and keys[-1][0] < t_first - lead - 0.08:
        keys.append((t_first - lead, rest, STOP))
    for (t, v), kind in zip(new, kinds):
        if keys and t <= keys[-1][0] + 0.08 and kind != APEX:
            continue
        if keys and t <= keys[-1][0]:  # an apex inside the previous hold: cut the hold
            while len(keys) > 1 and keys[-1][0] >= t - 0.05 and keys[-1][2] != APEX:
                keys.pop()
        keys.append((t, v, kind))


def stroke_tracks(script, style, t):
    """Keyframed tracks of ``script`` performed in ``style`` at frame times ``t`` (F,).

    Returns ``hand`` {"L","R"}: (F, 3) targets, ``torso_pitch`` (F,), ``head_pitch`` (F,),
    ``shrug`` {"L","R"}: (F,) and ``activity`` {"L","R"}: (F,) in [0, 1] (how far each hand is from rest).
    """
    dominant = "R" if style.handedness == "right" else "L"
    other = "L" if dominant == "R" else "R"
    hand_keys = {"L": [(0.0, REST_HAND, STOP)], "R": [(0.0, REST_HAND, STOP)]}
    body_keys = [(0.0, np.zeros(2), STOP)]
    shrug_keys = {"L": [(0.0, np.zeros(1), STOP)], "R": [(0.0, np.zeros(1), STOP)]}
    osc = {"L": np.zeros((len(t), 3)), "R": np.zeros((len(t), 3))}
    scale = np.array([style.width, 1.0, 1.0])
    lead = leave_lead(style.tempo)
    for s in script.strokes:
        keys = KEYS[s.kind]
        # preparation at least 0.28 s before the apex: fast styles stay within human joint speeds
        times = [s.apex + (min(k[0] / style.tempo, -0.28) if k[0] < 0 else k[0] / style.tempo) for k in keys]
        kinds = [APEX if k[0] == 0.0 else VIA for k in keys] + [STOP]  # ... then the rest pose
        gain = style.amplitude * s.intensity
        targets = [REST_HAND + gain * scale * (np.array(k[1], float) - REST_HAND) + [0, style.hand_height, 0]
                   for k in keys]
        sides = [dominant, other] if s.hands == "both" else [dominant]
        end = times[-1] + RETRACT / style.tempo
        for side in sides:
            _add_keys(hand_keys[side], list(zip(times + [end], targets + [REST_HAND])), kinds, REST_HAND, lead)
            _add_keys(shrug_keys[side], [(tk, np.array([gain * k[4]])) for tk, k in zip(times, keys)]
                      + [(end, np.zeros(1))], kinds, np.zeros(1), lead)
            if s.kind == "wave":
                hold = (t >= times[1]) & (t <= times[2])
                env = np.sin(np.pi * np.clip((t - times[1]) / (times[2] - times[1]), 0, 1)) * hold
                osc[side][:, 0] += gain * WAVE_AMP * env * np.sin(2 * np.pi * WAVE_HZ * style.tempo * (t - times[1]))
        body = [(tk, gain * np.array([k[2], k[3]], float)) for tk, k in zip(times, keys)]
        _add_keys(body_keys, body + [(end, np.zeros(2))], kinds, np.zeros(2), lead)

    def track(keys, interp):
        tk, vk, kinds = zip(*keys)
        return interp(tk, np.stack(vk), t, stops=[k != VIA for k in kinds])

    out = {"hand": {}, "shrug": {}, "activity": {}}
    for side in ("L", "R"):
        h = track(hand_keys[side], interpolate_hand_keys) + osc[side]
        out["hand"][side] = h
        out["activity"][side] = np.clip(np.linalg.norm(h - REST_HAND, axis=-1) / 40.0, 0.0, 1.0)
        out["shrug"][side] = track(shrug_keys[side], interpolate_keys)[:, 0]
    b = track(body_keys, interpolate_keys)
    out["torso_pitch"], out["head_pitch"] = b[:, 0], b[:, 1]
    return out

"""Named performance styles of the built-in synthetic data (docs/design.md §9).

A style is a transformation of *how* a content script is performed; the script (strokes, apex times,
audio) is fixed by the content. Every field is a known, documented number, so a style-transfer result can
be checked against the clip rendered directly in the target style (exact ground truth up to idle noise).

| style       | amplitude | tempo | hand_height cm | lean deg | tremor cm | smoothness s | handedness | head_pitch deg | sway | width |
|-------------|-----------|-------|----------------|----------|-----------|--------------|------------|----------------|------|-------|
| neutral     | 1.00      | 1.00  |  0             |  0       | 0.0       | 0.08         | right      |  0             | 1.0  | 1.00  |
| energetic   | 1.35      | 1.35  | +8             | +4       | 0.0       | 0.04         | right      | -4             | 1.5  | 1.20  |
| sad         | 0.50      | 0.65  | -12            | +14      | 0.0       | 0.16         | right      | +18            | 0.5  | 0.80  |
| tense       | 0.75      | 1.25  | +4             | +3       | 1.2       | 0.02         | right      | +4             | 0.3  | 0.70  |
| relaxed     | 0.90      | 0.80  | -4             | -2       | 0.0       | 0.22         | right      |  0             | 1.4  | 1.10  |
| left_handed | 1.00      | 1.00  |  0             |  0       | 0.0       | 0.08         | left       |  0             | 1.0  | 1.00  |
| proud       | 1.10      | 0.90  | +5             | -8       | 0.0       | 0.10         | right      | -10            | 0.8  | 1.30  |

Field meanings (all relative to ``neutral``):
  amplitude   scale of every stroke's hand displacement away from the rest hand position.
  tempo       speed of stroke preparation / hold / retraction and of oscillations (wave, idle);
              apexes stay on the content's audio onsets.
  hand_height vertical offset (cm) added to every stroke's hand target.
  lean        torso pitch in degrees, positive = forward (spine and chest share it).
  tremor      amplitude (cm) of 8-12 Hz band-limited hand jitter.
  smoothness  time constant (s) of the low-pass filter applied to the hand and torso trajectories.
  handedness  which hand performs the content's one-handed ("dominant") strokes.
  head_pitch  head pitch in degrees, positive = chin down.
  sway        scale of the idle motion (breathing, weight shift, head drift).
  width       scale of the lateral (sideways) hand displacement.
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class StyleParams:
    """Parameters of one synthetic style (see the module table)."""

    name: str
    amplitude: float = 1.0  # stroke displacement scale
    tempo: float = 1.0  # speed of stroke phases and oscillations
    hand_height: float = 0.0  # cm added to stroke hand targets
    lean: float = 0.0  # torso pitch, degrees, + forward
    tremor: float = 0.0  # cm of 8-12 Hz hand jitter
    smoothness: float = 0.08  # s, low-pass time constant
    handedness: str = "right"  # hand of one-handed strokes: "right" | "left"
    head_pitch: float = 0.0  # degrees, + chin down
    sway: float = 1.0  # idle motion scale
    width: float = 1.0  # lateral displacement scale

    def __post_init__(self):
        if self.handedness not in ("right", "left"):
            raise ValueError(f"StyleParams {self.name}: handedness must be 'right' or 'left'")
        if self.tempo <= 0 or self.amplitude < 0 or self.smoothness < 0 or self.tremor < 0:
            raise ValueError(f"StyleParams {self.name}: tempo > 0 and amplitude, smoothness, tremor >= 0")


STYLES: dict = {
    s.name: s
    for s in (
        StyleParams("neutral"),
        StyleParams("energetic", amplitude=1.35, tempo=1.35, hand_height=8.0, lean=4.0, smoothness=0.04,
                    head_pitch=-4.0, sway=1.5, width=1.2),
        StyleParams("sad", amplitude=0.5, tempo=0.65, hand_height=-12.0, lean=14.0, smoothness=0.16,
                    head_pitch=18.0, sway=0.5, width=0.8),
        StyleParams("tense", amplitude=0.75, tempo=1.25, hand_height=4.0, lean=3.0, tremor=1.2,
                    smoothness=0.02, head_pitch=4.0, sway=0.3, width=0.7),
        StyleParams("relaxed", amplitude=0.9, tempo=0.8, hand_height=-4.0, lean=-2.0, smoothness=0.22,
                    sway=1.4, width=1.1),
        StyleParams("left_handed", handedness="left"),
        StyleParams("proud", amplitude=1.1, tempo=0.9, hand_height=5.0, lean=-8.0, smoothness=0.10,
                    head_pitch=-10.0, sway=0.8, width=1.3),
    )
}


def get_style(style) -> StyleParams:
    """A :class:`StyleParams` from a name in :data:`STYLES` or a StyleParams (returned as is)."""
    if isinstance(style, StyleParams):
        return style
    try:
        return STYLES[style]
    except KeyError:
        raise KeyError(f"unknown synthetic style {style!r}; known: {', '.join(STYLES)}") from None

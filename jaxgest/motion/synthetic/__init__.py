"""Built-in synthetic gesture data with known styles (docs/design.md §9).

Seeded procedural gestures on the 21-joint body at 60 fps, paired with speech-like audio:

* a *content* (:mod:`.content`) is a script of gesture strokes (beat, point, wave, raise, bow, arms-open)
  whose apexes sit on stressed-syllable onsets of its audio; the hand stops only at apexes and at rest
  (:mod:`.strokes`), so the kinematic beats (hand-speed minima) of the clean motion fall near speech
  onsets (BeatAlign about 0.74 against 0.59 for shifted onsets, ``experiments/zeggs_synthetic/beat_diagnostic.py``);
* a *style* (:mod:`.styles`, table of :class:`StyleParams` there) says how the script is performed
  (amplitude, tempo, hand height, lean, tremor, smoothness, handedness, head pitch, idle sway, width);
* idle motion (breathing, weight shift, head drift) keeps every clip alive; the legs stand on fixed feet
  (two-bone IK), so the knees and hips move a little while the lowest foot joint stays on the floor.

Every content renders in every style with the same audio and stroke timing: the clip rendered in the
target style is the exact ground truth of a style transfer (up to the seeded idle/tremor noise, which
depends on ``seed`` only).

    motion, audio, sr = render_clip("greeting", "sad", seed=0)
    write_dataset("out/", clips=None, seed=0)   # 6 contents x 7 styles, BVH + WAV + manifest.csv
"""

from jaxgest.motion.synthetic.clips import FPS, SAMPLE_RATE, _rig, render_clip, smooth  # noqa: F401
from jaxgest.motion.synthetic.content import (  # noqa: F401
    CONTENTS,
    STROKE_TYPES,
    ContentSpec,
    Script,
    Stroke,
    get_content,
    make_script,
    speech_audio,
)
from jaxgest.motion.synthetic.dataset import write_dataset  # noqa: F401
from jaxgest.motion.synthetic.styles import STYLES, StyleParams, get_style  # noqa: F401

__all__ = [
    "CONTENTS",
    "STYLES",
    "STROKE_TYPES",
    "ContentSpec",
    "Script",
    "Stroke",
    "StyleParams",
    "get_content",
    "get_style",
    "make_script",
    "speech_audio",
    "render_clip",
    "write_dataset",
    "FPS",
    "SAMPLE_RATE",
]

"""Speech -> gestures -> style: ZeroEGGS generation followed by TGST style transfer (both papers chained).

Kuriyama et al. 2022 (§5) name as their final target the use of tokenized style transfer as a post-process
for speech-driven gesture generation; :func:`speech_to_styled_gestures` is that chain:

1. ZeroEGGS (:mod:`jaxgest.zeggs.inference`) generates gestures for the speech in the style of
   ``zeggs_style`` (a neutral reference clip, or any clip; default: the style exemplar itself);
2. TGST (:mod:`jaxgest.tgst.api`) transfers that motion to the style of the exemplar ``style``
   (content = the generated motion, whose timing follows the speech);
3. the result is put on the exemplar's skeleton (:func:`jaxgest.motion.body.to_rig`: through the joint
   maps with the feet on the floor when the rigs differ) and has ``round(duration x fps)`` frames at the
   exemplar's frame rate.

References: Kuriyama et al. 2022, §5 (future work); Ghorbani et al. 2023, §3.
"""

from __future__ import annotations

import pathlib
import time
from typing import Optional

from jaxgest.runtime.errors import DataError
from jaxgest.motion.body import to_rig
from jaxgest.motion.skeleton import Motion


def audio_duration(audio, sr: Optional[int] = None) -> float:
    """Seconds of an audio file (header only) or of an array at ``sr``."""
    if isinstance(audio, (str, pathlib.Path)):
        import soundfile as sf

        try:
            info = sf.info(str(audio))
        except Exception as e:  # soundfile raises its own error types; the models report the details
            raise DataError(f"{audio}: unreadable audio ({str(e).splitlines()[0]})") from None
        return info.frames / float(info.samplerate)
    if sr is None:
        raise DataError("an audio array needs its sample rate")
    return len(audio) / float(sr)


def speech_to_styled_gestures(audio, style: Motion, *, zeggs_workdir, tgst_workdir,
                              zeggs_style: Optional[Motion] = None, method: str = "soft", seed: int = 0,
                              temperature: float = 1.0, sr: Optional[int] = None,
                              style_input: str = "mirror") -> tuple[Motion, Motion, dict]:
    """Speech (path or array with ``sr``) -> (styled Motion on ``style``'s rig, ZEGGS output, timings in s).

    ``method`` and ``style_input`` (``"mirror"``: the exemplar followed by its mirror, the default; ``"as-is"``)
    as in :meth:`jaxgest.tgst.api.TGSTModel.transfer`.

    Raises the models' DataError / CheckpointError (bad audio, too-short clips, missing checkpoints).
    """
    from jaxgest.tgst.api import load_model as load_tgst
    from jaxgest.zeggs.inference import load_model as load_zeggs

    t0 = time.perf_counter()
    zeggs = load_zeggs(zeggs_workdir)
    tgst = load_tgst(tgst_workdir)
    t1 = time.perf_counter()
    generated = zeggs.generate(audio, [zeggs_style if zeggs_style is not None else style], seed=seed,
                               temperature=temperature, sr=sr, name="zeggs")
    t2 = time.perf_counter()
    styled = tgst.transfer(generated, style, method=method, name=f"speech in the style of {style.name or 'style'}",
                           style_input=style_input)
    styled = to_rig(styled, style, fps=style.fps, frames=max(1, int(round(audio_duration(audio, sr) * style.fps))))
    t3 = time.perf_counter()
    return styled, generated, {"load_s": t1 - t0, "zeggs_s": t2 - t1, "tgst_s": t3 - t2}

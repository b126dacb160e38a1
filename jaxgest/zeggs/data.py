"""ZeroEGGS training data: aligned speech/pose features, augmentation, normalisation, batches.

From a folder (ZEGGS layout with WAVs, or a ``manifest.csv`` with an ``audio`` column such as the
built-in synthetic data) to fixed-size training batches (paper 001 §4.1, §4.3):

* every clip is resampled to the model rate explicitly (``resample_motion``), its pose features
  extracted (:func:`jaxgest.zeggs.features.extract_features`) and its speech features computed at the
  same rate (:func:`jaxgest.audio.speech_features`); audio and motion may differ in length by at most
  ``LENGTH_TOLERANCE_S`` seconds (both are cut to the shorter), more is a :class:`DataError`;
* augmentation: the mirrored motion with the same audio (``kinematics.mirror``), and speed changes of
  ±10 %: motion and speech features are resampled together in time (the speech by interpolating its
  feature frames, i.e. a time stretch without pitch change), at the factors ``SPEEDS``;
* normalisation: per-channel mean/std of pose and speech features over all training frames
  (``NormStats``), saved beside the model;
* a batch (pure function of ``(seed, step)``, so a resumed run sees the same data) holds ``batch`` target
  windows of ``window`` frames and, for each, a style window of a random length in
  ``[style_min, style_max]`` frames (padded to ``style_max`` with a mask), drawn by one of the
  ``SAMPLING_MODES`` (:func:`style_window`):

  - ``overlap`` (the paper, §4.3): from the same sequence, containing the target window;
  - ``disjoint``: from the same sequence, not overlapping the target window (before or after it);
  - ``other-clip``: from a sequence of *another* clip with the same style label and the same variant
    (mirrored or not, same speed) as the target; a sequence whose style has no other clip falls back to
    ``disjoint``. The variant must match: a mirrored performance swaps the dominant hand, so the mirror of a
    right-handed style is a left-handed one (on the synthetic data ``neutral`` and ``left_handed`` differ
    only by that), and a style example of the other variant would teach the encoder to ignore handedness.

  docs/design.md §4 allows a style window apart from the target if it is measured against the paper's; the
  comparison (leakage report, probes) is in ``experiments/zeggs_synthetic/README.md``.

Batch layout (float32 unless said)::

    speech        (B, T, 81)  normalised speech features
    pose          (B, T, P)   normalised target pose features (P = 15 j + 6)
    root_position (B, T, 3)   target root positions (cm), relative to the window's first root position
    root_rotation (B, T, 4)   target root yaw quaternions, relative to the window's first root rotation
    style         (B, S, P)   normalised style pose features, S = style_max
    style_mask    (B, S)      bool, True on real frames
    facing        (B, 3)      target facing direction (world, ground plane, unit), in the window's frame

References: Ghorbani et al. 2023, §4.1 (data preparation, mirroring, target facing direction), §4.3
(T = 256, style window 256-512 containing the target, ±10 % speed augmentation).
"""

from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.motion import kinematics
from jaxgest.motion import rotations
from jaxgest.motion.datasets import Clip, NormStats, load_clip_audio, load_folder, resample_motion
from jaxgest.zeggs import features

LENGTH_TOLERANCE_S = 1.0
SAMPLING_MODES = ("overlap", "disjoint", "other-clip")
SPEEDS = (0.9, 1.0, 1.1)
WORLD_FORWARD = np.array([0.0, 0.0, 1.0])


@dataclasses.dataclass
class AlignedSequence:
    """One training sequence (a clip, maybe mirrored / sped up) at the model rate."""

    name: str
    style: str
    pose: np.ndarray  # (F, P) float32, un-normalised
    speech: np.ndarray  # (F, 81) float32, un-normalised
    root_position: np.ndarray  # (F, 3)
    root_rotation: np.ndarray  # (F, 4)
    facing: np.ndarray  # (3,) world facing target of the clip
    clip: str = ""  # the source clip (same for its mirrored / sped-up variants)
    content: str = ""  # the source clip's content label
    mirrored: bool = False  # the left/right mirror of the source clip
    speed: float = 1.0  # playback speed factor of the augmentation (1.0 = as recorded)

    @property
    def frames(self) -> int:
        return int(self.pose.shape[0])


def clip_facing(root_rotation: np.ndarray) -> np.ndarray:
    """The clip's target facing direction: the median root forward direction, on the ground, unit.

    The paper takes the median of the projected head z-axis; the root's forward (hips) is used here
    because it exists on every rig. References: Ghorbani et al. 2023, §4.1.
    """
    fwd = rotations.quat_rotate(root_rotation, np.broadcast_to(WORLD_FORWARD, root_rotation.shape[:-1] + (3,)))
    med = np.median(fwd, axis=0)
    med[1] = 0.0
    n = np.linalg.norm(med)
    return med / n if n > 1e-6 else WORLD_FORWARD.copy()


def _time_resample(x: np.ndarray, frames: int) -> np.ndarray:
    """Linear interpolation of ``(F, C)`` features to ``frames`` frames (same start and end)."""
    src = np.linspace(0.0, 1.0, x.shape[0])
    dst = np.linspace(0.0, 1.0, frames)
    return np.stack([np.interp(dst, src, x[:, c]) for c in range(x.shape[1])], axis=1).astype(np.float32)


def clip_sequences(clip: Clip, *, fps: float, mirror: bool = True, speeds: Sequence[float] = SPEEDS,
                   min_frames: int = 2, loudness: bool = True,
                   speech_method: str = "authors") -> list[AlignedSequence]:
    """All training sequences of one clip (original, mirrored; each at every speed); ``loudness`` and
    ``speech_method`` are :func:`jaxgest.audio.speech_features`'s (the model's ``loudness`` and
    ``speech_features``)."""
    from jaxgest.audio import speech_features

    if clip.audio is None:
        raise DataError(f"{clip.path}: no audio next to this clip (ZeroEGGS trains on speech + motion)")
    samples, sr = load_clip_audio(clip)
    speech = np.asarray(speech_features(samples, sr=sr, fps=fps, loudness=loudness, method=speech_method),
                        np.float32)
    out = []
    variants = [("", clip.motion)] + ([("_mirror", kinematics.mirror(clip.motion))] if mirror else [])
    for suffix, motion in variants:
        for speed in speeds:
            # Playing `speed` times faster: the same poses over 1/speed of the time.
            m = resample_motion(motion.replace(fps=motion.fps * speed), fps)
            feats = features.extract_features(m)
            pose = feats["features"]
            sp = speech if speed == 1.0 else _time_resample(speech, max(2, int(round(len(speech) / speed))))
            diff = abs(len(sp) - len(pose)) / fps
            if diff > LENGTH_TOLERANCE_S / speed:
                raise DataError(
                    f"{clip.path}: audio ({len(speech) / fps:.2f} s) and motion ({motion.duration:.2f} s) "
                    f"lengths differ by more than {LENGTH_TOLERANCE_S} s"
                )
            n = min(len(sp), len(pose))
            if n < min_frames:
                continue
            rot = feats["root_rotation"][:n]
            out.append(AlignedSequence(
                name=f"{clip.path.stem if clip.path else clip.content}{suffix}@{speed:g}",
                style=clip.style, pose=pose[:n], speech=sp[:n], root_position=feats["root_position"][:n],
                root_rotation=rot, facing=clip_facing(rot), clip=str(clip.path) if clip.path else clip.content,
                content=clip.content, mirrored=bool(suffix), speed=float(speed)))
    return out


@dataclasses.dataclass
class ZeggsData:
    """Sequences plus normalisation statistics; :meth:`batch` draws a training batch."""

    sequences: list
    pose_stats: NormStats
    speech_stats: NormStats
    fps: float
    skeleton: object  # the rig of the data (all clips must share it)

    @property
    def pose_dim(self) -> int:
        return int(self.sequences[0].pose.shape[1])

    def batch(self, step: int, *, seed: int, batch: int, window: int, style_min: int, style_max: int,
              sampling: str = "overlap") -> dict:
        """Batch of ``step`` (deterministic in ``(seed, step)``); layout in the module docstring; style
        windows drawn by ``sampling`` (one of ``SAMPLING_MODES``, see :func:`style_window`)."""
        if sampling not in SAMPLING_MODES:
            raise DataError(f"unknown style sampling mode {sampling!r}; choose from {', '.join(SAMPLING_MODES)}")
        rng = np.random.default_rng([seed, step])
        lengths = np.array([s.frames for s in self.sequences])
        need = window + style_min if sampling == "disjoint" else max(window, style_min)
        ok = np.flatnonzero(lengths >= need)
        if len(ok) == 0:
            longest = self.sequences[int(np.argmax(lengths))]
            raise DataError(f"no clip is long enough: longest {longest.name} has {longest.frames} frames, "
                            f"a batch needs {need} at {self.fps:g} fps"
                            + (" (style sampling 'disjoint': target + style window)" if sampling == "disjoint" else ""))
        p = lengths[ok] / lengths[ok].sum()
        P = self.pose_dim
        out = {
            "speech": np.zeros((batch, window, 81), np.float32),
            "pose": np.zeros((batch, window, P), np.float32),
            "root_position": np.zeros((batch, window, 3), np.float32),
            "root_rotation": np.zeros((batch, window, 4), np.float32),
            "style": np.zeros((batch, style_max, P), np.float32),
            "style_mask": np.zeros((batch, style_max), bool),
            "facing": np.zeros((batch, 3), np.float32),
        }
        for b in range(batch):
            i = int(ok[rng.choice(len(ok), p=p)])
            s = self.sequences[i]
            t0, (j, s0, m) = style_window(self.sequences, i, rng, window=window, style_min=style_min,
                                          style_max=style_max, sampling=sampling)
            for k, v in target_arrays(s, t0, window, self.pose_stats, self.speech_stats).items():
                out[k][b] = v
            out["style"][b, :m] = self.pose_stats.normalize(self.sequences[j].pose[s0:s0 + m])
            out["style_mask"][b, :m] = True
        return out


def target_arrays(s: AlignedSequence, t0: int, window: int, pose_stats: NormStats, speech_stats: NormStats) -> dict:
    """The target part of one batch row (frames ``[t0, t0 + window)`` of ``s``): ``speech``, ``pose``
    (normalised), ``root_position`` / ``root_rotation`` relative to the window's first frame and ``facing``
    in that frame (layout in the module docstring, without the batch axis)."""
    sl = slice(t0, t0 + window)
    inv0 = rotations.quat_inv(s.root_rotation[t0])
    return {"speech": speech_stats.normalize(s.speech[sl]), "pose": pose_stats.normalize(s.pose[sl]),
            "root_position": rotations.quat_rotate(inv0, s.root_position[sl] - s.root_position[t0]),
            "root_rotation": rotations.quat_mul(inv0, s.root_rotation[sl]),
            "facing": rotations.quat_rotate(inv0, s.facing)}


def style_window(sequences, i: int, rng, *, window: int, style_min: int, style_max: int,
                 sampling: str = "overlap"):
    """A target window of sequence ``i`` and its style window: ``(t0, (j, s0, m))``.

    The target is frames ``[t0, t0 + window)`` of ``sequences[i]``; the style window is frames
    ``[s0, s0 + m)`` of ``sequences[j]``, ``m`` in ``[style_min, style_max]`` (capped by what fits):

    * ``overlap``: ``j = i``, the style window contains the target (the paper, §4.3), or lies inside it
      when the target is longer;
    * ``disjoint``: ``j = i``, ``[s0, s0 + m)`` and ``[t0, t0 + window)`` do not intersect (needs
      ``frames >= window + style_min``; the target start is redrawn until one side has room, after 32
      draws the target starts at 0);
    * ``other-clip``: ``j`` is a sequence of another source clip with the same style label and the same
      variant (``mirrored`` and ``speed``; uniform over those at least ``style_min`` frames long), the
      window anywhere in it; without one, ``disjoint``.

    ``rng`` is a ``numpy.random.Generator`` (the batch's), so the draw is deterministic in it.
    """
    s = sequences[i]
    F = s.frames
    if sampling == "other-clip":
        others = [k for k, o in enumerate(sequences)
                  if o.style == s.style and o.clip != s.clip and o.frames >= style_min
                  and o.mirrored == s.mirrored and o.speed == s.speed]
        if others:
            t0 = int(rng.integers(0, F - window + 1))
            j = others[int(rng.integers(len(others)))]
            Fj = sequences[j].frames
            m = int(rng.integers(style_min, min(style_max, Fj) + 1))
            return t0, (j, int(rng.integers(0, Fj - m + 1)), m)
        sampling = "disjoint" if F >= window + style_min else "overlap"
    if sampling == "disjoint":
        for _ in range(32):
            t0 = int(rng.integers(0, F - window + 1))
            room = max(t0, F - t0 - window)
            if room >= style_min:
                break
        else:
            t0, room = 0, F - window
        m = int(rng.integers(style_min, min(style_max, room) + 1))
        sides = [lo_hi for lo_hi in ((0, t0 - m), (t0 + window, F - m)) if lo_hi[1] >= lo_hi[0]]
        lo, hi = sides[int(rng.integers(len(sides)))]
        return t0, (i, int(rng.integers(lo, hi + 1)), m)
    t0 = int(rng.integers(0, F - window + 1))
    m = int(rng.integers(style_min, min(style_max, F) + 1))
    m = max(m, min(window, F))
    lo, hi = max(0, t0 + window - m), min(t0, F - m)
    s0 = int(rng.integers(lo, hi + 1)) if hi >= lo else max(0, min(t0, F - m))
    return t0, (i, s0, m)


def build(clips: Sequence[Clip], *, fps: float, mirror: bool = True, speeds: Sequence[float] = SPEEDS,
          pose_stats: Optional[NormStats] = None, speech_stats: Optional[NormStats] = None,
          progress: bool = False, loudness: bool = True, input_norm: str = "group",
          speech_method: str = "authors") -> ZeggsData:
    """Sequences of every clip and (unless given) the normalisation statistics fitted on them."""
    if not clips:
        raise DataError("no clips to train on")
    names = clips[0].motion.skeleton.names
    for c in clips[1:]:
        if c.motion.skeleton.names != names:
            raise DataError(f"{c.path}: skeleton differs from {clips[0].path}; ZeroEGGS trains on one rig")
    from tqdm.auto import tqdm

    seqs = []
    for c in tqdm(clips, desc="features", disable=not progress, leave=False):
        seqs.extend(clip_sequences(c, fps=fps, mirror=mirror, speeds=speeds, loudness=loudness,
                                   speech_method=speech_method))
    if not seqs:
        raise DataError("every clip is too short to use")
    pose_stats = pose_stats or features.pose_statistics([s.pose for s in seqs], input_norm=input_norm)
    speech_stats = speech_stats or NormStats.from_data([s.speech for s in seqs])
    return ZeggsData(seqs, pose_stats, speech_stats, fps, clips[0].motion.skeleton)


def exclude_styles(clips, styles: Sequence[str], data_dir=None) -> list:
    """``clips`` without those of the ``styles`` left out of training (``TrainConfig.exclude_styles``).
    :class:`DataError` (one line naming ``data_dir``) for a style the data does not have, or when no clip is
    left. References: Ghorbani et al. 2023, §5.1 (styles unseen in training)."""
    styles = tuple(styles)
    if not styles:
        return list(clips)
    where = f"{data_dir}: " if data_dir is not None else ""
    have = {c.style for c in clips}
    missing = [s for s in styles if s not in have]
    if missing:
        raise DataError(f"{where}exclude_styles names style(s) the data does not have: {', '.join(missing)} "
                        f"(styles: {', '.join(sorted(have, key=str))})")
    kept = [c for c in clips if c.style not in styles]
    if not kept:
        raise DataError(f"{where}exclude_styles leaves no clip to train on")
    return kept


def load(data_dir, *, fps: float, **kw) -> ZeggsData:
    """:func:`build` on every clip of a folder that has audio."""
    clips = [c for c in load_folder(data_dir) if c.audio is not None]
    if not clips:
        raise DataError(f"{data_dir}: no clip has audio (ZeroEGGS needs BVH + WAV pairs)")
    return build(clips, fps=fps, **kw)

"""Folder datasets (Bandai-Namco, ZEGGS, manifest.csv), random windows, normalisation stats, resampling.

Layouts recognised by :func:`load_folder` (docs/design.md §6):

* ``manifest.csv`` with columns ``path, content, style[, audio]`` (paths relative to the folder) -- the
  built-in synthetic data (:mod:`jaxgest.motion.synthetic`) is written this way;
* Bandai-Namco: ``dataset-1_{content}_{style}_{id}.bvh``; content and style names never contain ``_``
  but may contain ``-`` (``raise-up-both-hands``, ``not-confident``);
* ZEGGS: ``NNN_{Style}_{k}_x_1_0.bvh`` (the processed, already trimmed files) or the dataset's own
  ``NNN_{Style}_{k}.bvh``, each with an optional ``.wav`` of the same stem; content = the file stem. For
  the raw ``NNN_Style_k.bvh`` files an ``info.csv`` in the folder (the ZEGGS release's) gives the acting
  range, which is cut from the motion (and recorded as the audio start offset), following the timecode
  arithmetic of the authors' ``data_pipeline.py``: animation timecodes count 1/60 s frames, audio
  timecodes 1/30 s frames.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import pathlib
import re
from typing import NamedTuple, Optional, Sequence

import numpy as np

from jaxgest.runtime.errors import CheckpointError, DataError
from jaxgest.motion import rotations as rot
from jaxgest.motion.skeleton import Motion

BANDAI_RE = re.compile(r"^dataset-\d+_(?P<content>[A-Za-z0-9-]+)_(?P<style>[A-Za-z0-9-]+)_(?P<id>\d+)\.bvh$")
ZEGGS_RE = re.compile(r"^(?P<num>\d{3})_(?P<style>[A-Za-z]+)_(?P<k>\d+)(?P<x>_x_1_0)?(?P<mirror>_mirror)?\.bvh$")


@dataclasses.dataclass(frozen=True, eq=False)
class Clip:
    """One motion clip of a dataset.

    Attributes:
      motion: the :class:`Motion` (trimmed where the layout says so).
      content: content label (Bandai: the action, ZEGGS: the file stem, manifest: its column).
      style: style label.
      path: the BVH file.
      audio: the matching WAV, or None.
      audio_start: seconds into ``audio`` where the motion's first frame is (ZEGGS raw-file trims).
    """

    motion: Motion
    content: str
    style: str
    path: pathlib.Path
    audio: Optional[pathlib.Path] = None
    audio_start: float = 0.0


def dataset_root(folder) -> pathlib.Path:
    """The folder holding the clips: ``folder`` itself, or its ``data/`` subfolder when ``folder`` has no BVH
    and no manifest.csv (the Bandai-Namco repository keeps its BVH files in ``dataset-1/data/``)."""
    folder = pathlib.Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: not a directory")
    has_clips = (folder / "manifest.csv").is_file() or any(p.suffix.lower() == ".bvh" for p in folder.iterdir())
    if not has_clips and (folder / "data").is_dir():
        return folder / "data"
    return folder


def detect_layout(folder) -> str:
    """``"manifest"``, ``"bandai"`` or ``"zeggs"``; DataError for a missing/empty folder or unknown names."""
    folder = pathlib.Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: not a directory")
    if (folder / "manifest.csv").is_file():
        return "manifest"
    names = sorted(p.name for p in folder.iterdir() if p.suffix.lower() == ".bvh")
    if not names:
        raise DataError(f"{folder}: no .bvh files and no manifest.csv")
    for layout, pattern in (("bandai", BANDAI_RE), ("zeggs", ZEGGS_RE)):
        if all(pattern.match(n) for n in names):
            return layout
    odd = next(n for n in names if not (BANDAI_RE.match(n) or ZEGGS_RE.match(n)))
    raise DataError(
        f"{folder}: unknown dataset layout (file {odd!r}); expected manifest.csv, "
        "dataset-1_{content}_{style}_{id}.bvh (Bandai-Namco) or NNN_{Style}_{k}[_x_1_0].bvh (ZEGGS)"
    )


def load_folder(folder, progress: bool = False) -> list:
    """Every clip of a dataset folder, sorted by file name (see the module docstring for layouts)."""
    from tqdm import tqdm

    from jaxgest.motion import bvh

    folder = dataset_root(folder)
    layout = detect_layout(folder)
    entries = {"manifest": _manifest_entries, "bandai": _bandai_entries, "zeggs": _zeggs_entries}[layout](folder)
    if not entries:
        raise DataError(f"{folder}: the dataset has no clips")
    trims = _zeggs_trims(folder) if layout == "zeggs" else {}
    clips = []
    for path, content, style, audio in tqdm(entries, desc="load", unit="clip", disable=not progress):
        motion = bvh.load(path)
        audio_start = 0.0
        if path.name in trims:
            motion, audio_start = _apply_trim(motion, trims[path.name], folder / "info.csv")
        clips.append(Clip(motion, content, style, path, audio, audio_start))
    return clips


def _bandai_entries(folder):
    out = []
    for p in sorted(folder.glob("*.bvh")):
        m = BANDAI_RE.match(p.name)
        out.append((p, m["content"], m["style"], None))
    return out


def _zeggs_entries(folder):
    out = []
    for p in sorted(folder.glob("*.bvh")):
        m = ZEGGS_RE.match(p.name)
        wav = p.with_suffix(".wav")
        out.append((p, p.stem, m["style"], wav if wav.is_file() else None))
    return out


def _manifest_entries(folder):
    path = folder / "manifest.csv"
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            fields = set(reader.fieldnames or ())
            missing = {"path", "content", "style"} - fields
            if missing:
                raise DataError(f"{path}: missing column(s) {', '.join(sorted(missing))}")
            rows = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise DataError(f"{path}: unreadable manifest ({e})") from None
    out = []
    for line, row in enumerate(rows, start=2):
        if not (row.get("path") or "").strip():
            raise DataError(f"{path}:{line}: empty path")
        bvh_path = folder / row["path"].strip()
        if not bvh_path.is_file():
            raise DataError(f"{path}:{line}: file {bvh_path} does not exist")
        audio = (row.get("audio") or "").strip()
        audio_path = folder / audio if audio else None
        if audio_path is not None and not audio_path.is_file():
            raise DataError(f"{path}:{line}: audio file {audio_path} does not exist")
        out.append((bvh_path, row["content"].strip(), row["style"].strip(), audio_path))
    return out


def _timecode(text: str, frame_units: int, where: str) -> int:
    """HH:MM:SS:FF -> time in 1/60 s units; ``frame_units`` = 1/60 s units per FF (1 anim, 2 audio)."""
    try:
        h, m, s, f = (int(x) for x in text.strip().split(":"))
    except ValueError:
        raise DataError(f"{where}: bad timecode {text!r}") from None
    return h * 216000 + m * 3600 + s * 60 + f * frame_units


def _zeggs_trims(folder):
    """{raw bvh name: (start, end in 1/60 s relative to the animation, audio start in 1/60 s)} from info.csv."""
    info = folder / "info.csv"
    if not info.is_file():
        return {}
    try:
        with open(info, newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise DataError(f"{info}: unreadable ({e})") from None
    trims = {}
    for line, row in enumerate(rows, start=2):
        name = (row.get("anim_bvh") or "").strip()
        if not name:
            continue
        where = f"{info}:{line}"
        try:
            anim0 = _timecode(row["anim_start_time"], 1, where)
            audio0 = _timecode(row["audio_start_time"], 2, where)
            a = _timecode(row["acting_start_time"], 1, where)
            b = _timecode(row["acting_end_time"], 1, where)
        except KeyError as e:
            raise DataError(f"{where}: missing column {e}") from None
        if a < anim0 or b <= a or a < audio0:
            raise DataError(f"{where}: acting range {row['acting_start_time']}..{row['acting_end_time']} "
                            "is outside the recording")
        trims[name] = (a - anim0, b - anim0, a - audio0)
    return trims


def _apply_trim(motion: Motion, trim, info_path):
    start, end, audio_start = trim
    f0 = int(round(start * motion.fps / 60.0))
    f1 = min(int(round(end * motion.fps / 60.0)), motion.num_frames)
    if f1 - f0 < 2:
        raise DataError(f"{info_path}: acting range of {motion.name} leaves {max(f1 - f0, 0)} frames")
    m = motion.replace(rotations=motion.rotations[f0:f1], translations=motion.translations[f0:f1])
    return m, audio_start / 60.0


def load_clip_audio(clip: Clip, sr: Optional[int] = None):
    """The clip's audio ``(samples,), sr`` aligned with its first frame (trim applied), mono float32."""
    import soundfile as sf

    from jaxgest.runtime.errors import AudioError

    if clip.audio is None:
        raise AudioError(f"{clip.path}: no audio file")
    try:
        y, file_sr = sf.read(str(clip.audio), dtype="float32", always_2d=True)
    except (RuntimeError, OSError, sf.LibsndfileError) as e:
        raise AudioError(f"{clip.audio}: unreadable audio ({e})") from None
    y = y.mean(axis=1)
    y = y[int(round(clip.audio_start * file_sr)):]
    if sr is not None and sr != file_sr:
        import librosa

        y = librosa.resample(y, orig_sr=file_sr, target_sr=sr)
        file_sr = sr
    return y.astype(np.float32), int(file_sr)


class Windows(NamedTuple):
    """Random windows: ``index`` (B,) clip indices, ``start`` (B,) first frames, ``data`` the windows
    ((B, length, ...) array for array inputs, a list of Motions for Clip/Motion inputs)."""

    index: np.ndarray
    start: np.ndarray
    data: object


def _length(item) -> int:
    if isinstance(item, Clip):
        return item.motion.num_frames
    if isinstance(item, Motion):
        return item.num_frames
    return int(np.shape(item)[0])


def _label(item, i) -> str:
    if isinstance(item, Clip):
        return str(item.path)
    if isinstance(item, Motion) and item.name:
        return item.name
    return f"clip {i}"


def slice_motion(m: Motion, start: int, length: int) -> Motion:
    """Frames ``start .. start + length`` of ``m``."""
    return m.replace(rotations=m.rotations[start:start + length], translations=m.translations[start:start + length])


def sample_windows(clips: Sequence, length: int, batch: int, rng: np.random.Generator) -> Windows:
    """``batch`` random windows of ``length`` frames, uniform over all valid (clip, start) pairs.

    ``clips`` holds Clips, Motions or arrays (frames first). Clips shorter than ``length`` are skipped;
    DataError when none is long enough (naming the longest and the shortest clip and the window).
    """
    if not len(clips):
        raise DataError("sample_windows: no clips")
    length, batch = int(length), int(batch)
    lengths = np.array([_length(c) for c in clips])
    valid = np.maximum(lengths - length + 1, 0)
    if valid.sum() == 0:
        lo, hi = int(np.argmin(lengths)), int(np.argmax(lengths))
        raise DataError(
            f"no clip is long enough for a {length}-frame window: the longest, {_label(clips[hi], hi)}, has "
            f"{lengths[hi]} frames (the shortest, {_label(clips[lo], lo)}, has {lengths[lo]})"
        )
    index = rng.choice(len(clips), size=batch, p=valid / valid.sum())
    start = np.array([rng.integers(0, valid[i]) for i in index], dtype=np.int64)
    first = clips[0]
    if isinstance(first, (Clip, Motion)):
        data = [slice_motion(clips[i].motion if isinstance(clips[i], Clip) else clips[i], s, length)
                for i, s in zip(index, start)]
    else:
        data = np.stack([np.asarray(clips[i])[s:s + length] for i, s in zip(index, start)])
    return Windows(index.astype(np.int64), start, data)


@dataclasses.dataclass(frozen=True)
class NormStats:
    """Per-channel mean and std over frames (and clips) of a feature array, std floored at ``eps``.

    ``normalize`` / ``denormalize`` accept NumPy or JAX arrays (..., C); the stats are cast to the input's
    dtype so strict dtype promotion holds.
    """

    mean: np.ndarray  # (C,) or feature shape
    std: np.ndarray
    eps: float = 1e-2

    @classmethod
    def from_data(cls, data, eps: float = 1e-2) -> "NormStats":
        """Stats of an array (..., frames, C) or a list of (frames_i, C) arrays (unequal lengths)."""
        if isinstance(data, (list, tuple)):
            if not data:
                raise DataError("NormStats: no data")
            x = np.concatenate([np.asarray(d, np.float64).reshape(-1, np.shape(d)[-1]) for d in data], 0)
        else:
            x = np.asarray(data, np.float64)
            x = x.reshape(-1, x.shape[-1])
        if x.shape[0] == 0 or not np.all(np.isfinite(x)):
            raise DataError("NormStats: empty or non-finite features")
        return cls(x.mean(0), np.maximum(x.std(0), eps), float(eps))

    def _cast(self, x):
        """mean, std in x's array library and dtype, with explicit leading axes (strict rank promotion)."""
        import jax

        lead = (1,) * (np.ndim(x) - self.mean.ndim)
        mean, std = self.mean.reshape(lead + self.mean.shape), self.std.reshape(lead + self.std.shape)
        if isinstance(x, jax.Array):
            import jax.numpy as jnp

            return jnp.asarray(mean, x.dtype), jnp.asarray(std, x.dtype)
        dt = np.asarray(x).dtype
        return mean.astype(dt, copy=False), std.astype(dt, copy=False)

    def normalize(self, x):
        mean, std = self._cast(x)
        return (x - mean) / std

    def denormalize(self, x):
        mean, std = self._cast(x)
        return x * std + mean

    def save(self, path) -> None:
        path = pathlib.Path(path)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(json.dumps({"mean": self.mean.tolist(), "std": self.std.tolist(), "eps": self.eps}))
        tmp.replace(path)

    @classmethod
    def load(cls, path) -> "NormStats":
        path = pathlib.Path(path)
        try:
            d = json.loads(path.read_text())
            return cls(np.asarray(d["mean"], np.float64), np.asarray(d["std"], np.float64), float(d["eps"]))
        except FileNotFoundError:
            raise CheckpointError(f"{path}: normalisation stats not found") from None
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise CheckpointError(f"{path}: unreadable normalisation stats ({e})") from None


def resample_weights(num_frames: int, src_fps: float, dst_fps: float, frames: int):
    """Interpolation of ``frames`` frames at ``k / dst_fps`` from ``num_frames`` frames at ``src_fps``.

    Returns ``(i0, i1, w)``: the two source frames around each new frame time and the weight of ``i1``
    (times past the last source frame hold it).
    """
    pos = np.arange(frames) * (float(src_fps) / float(dst_fps))
    i0 = np.minimum(np.floor(pos).astype(int), num_frames - 1)
    i1 = np.minimum(i0 + 1, num_frames - 1)
    return i0, i1, np.clip(pos - i0, 0.0, 1.0)


def fit_frames(motion: Motion, frames: int) -> Motion:
    """Cut ``motion`` to ``frames`` frames, or pad it by holding its last frame."""
    idx = np.minimum(np.arange(int(frames)), motion.num_frames - 1)
    return motion.replace(rotations=motion.rotations[idx], translations=motion.translations[idx])


def resample_motion(motion: Motion, fps: float) -> Motion:
    """``motion`` at ``fps``: slerp of rotations and lerp of translations at the new frame times.

    The new clip covers the same time span (frames at k / fps for k = 0 .. floor((F - 1) * fps / src)).
    """
    fps = float(fps)
    if fps <= 0:
        raise DataError(f"resample_motion: fps must be positive, got {fps}")
    if abs(fps - motion.fps) < 1e-9:
        return motion
    F = motion.num_frames
    n = int(np.floor((F - 1) * fps / motion.fps + 1e-9)) + 1
    i0, i1, w = resample_weights(F, motion.fps, fps, n)
    q = rot.quat_slerp(motion.rotations[i0], motion.rotations[i1], np.broadcast_to(w[:, None], (n, motion.rotations.shape[1])))
    tr = motion.translations[i0] * (1 - w)[:, None, None] + motion.translations[i1] * w[:, None, None]
    return motion.replace(rotations=q, translations=tr, fps=fps)

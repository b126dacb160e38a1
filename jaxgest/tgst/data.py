"""TGST training data: dataset clips -> body exp-maps at the model rate, and deterministic batches.

* :func:`prepare_clips` -- every clip of :func:`jaxgest.motion.datasets.load_folder` is resampled
  explicitly to ``cfg.model.fps`` (Bandai-Namco is 30 fps, the synthetic data 60 fps, the paper's 60 fps),
  converted by :func:`jaxgest.motion.body.motion_to_body` (root yaw removed) to upper ``(F, 39)`` and
  lower ``(F, 24)`` float32 exp-maps, and mirrored once (:func:`jaxgest.motion.kinematics.mirror`) for the
  style augmentation.
* :func:`fit_windows` -- windows scaled to the data. The paper's windows (256 / 1280 frames at 60 fps) are
  longer than many Bandai-Namco clips (4-15 s), and padding would teach the models frozen tails, so each
  window is ``min(preset window, median usable clip length rounded down to a multiple of 16)``: at least
  half of the clips then contribute windows. DataError when the longest clip is shorter than one token
  (16 frames), or when fewer than two clips are usable for content/style pairs.
* :func:`ae_batch` -- autoencoder batches: windows uniform over all valid (clip, start) pairs of the
  original AND the mirrored clips (mirrored poses are fed to the encoder at transfer time, so the
  autoencoder sees them too; the paper does not say whether its AE data was mirrored).
* :func:`transformer_batch` -- random UNALIGNED content/style pairs: two different clips drawn uniformly
  (§4.1, "randomly and evenly sampled"), a random content window; the style is
  ``cfg.train.transformer.style_tokens="window"``: a random window of the other clip, mirrored with
  probability 0.5; ``"clip_and_mirror"``: the other clip whole followed by its mirror (blended over 0.5 s,
  :func:`append_mirror`), one token set as in the authors' trainer (``setup_style_tokens``), padded to a
  length bucket with a mask of its real tokens (``"style_valid"``).

Every batch is a pure function of ``(seed, step)`` (``numpy.random.default_rng([seed, stage, step])``), so a
killed run resumes bit-identically.
References: Kuriyama et al. 2022, §3.5 and §4.1.
"""

from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.motion import body, datasets, kinematics
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion
from jaxgest.tgst.config import Config

AE_STAGE, TRANSFORMER_STAGE = 1, 2  # stream ids of the two stages' random batches
#: what every TGST checkpoint was trained on (compared on restore)
BODY_SIGNATURE = f"tgst-body21(upper{body.UPPER_CHANNELS},lower{body.LOWER_CHANNELS}):" + ",".join(body.BODY)


@dataclasses.dataclass(frozen=True, eq=False)
class BodyData:
    """Clips in the body representation at the model rate.

    Attributes:
      upper / lower: lists of ``(F_i, 39)`` / ``(F_i, 24)`` float32 arrays, one per clip.
      mirrored_upper / mirrored_lower: the same clips mirrored about the sagittal plane.
      names: clip labels (file paths) for error messages.
      fps: the model rate.
      contents: the content label of each clip (for content-balanced autoencoder windows), or None.
    """

    upper: list
    lower: list
    mirrored_upper: list
    mirrored_lower: list
    names: list
    fps: float
    contents: Optional[list] = None  # content label of each clip (datasets.Clip.content), None if unknown

    @property
    def lengths(self) -> np.ndarray:
        return np.array([u.shape[0] for u in self.upper], dtype=np.int64)


def motion_to_arrays(motion: Motion, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """A motion on any mapped rig -> (upper ``(F, 39)``, lower ``(F, 24)``) float32 at ``fps``."""
    bc = body.motion_to_body(datasets.resample_motion(motion, fps))
    return bc.upper.astype(np.float32), bc.lower.astype(np.float32)


def rig_tpose(skeleton) -> np.ndarray:
    """World rotations ``(J, 4)`` of a mapped rig's joints in its T-pose (the mirror's symmetric reference).

    Bandai-Namco layout (a map with ``tpose_axes``): the body joints' T-pose axes by name, other joints
    (the static ``joint_Root`` wrapper) their parent's (the root: identity). Maps with a rest T-pose
    (ZEGGS): the rig's rest pose (:func:`jaxgest.motion.body.tpose_globals`).
    """
    name = body.detect_map(skeleton)
    jm = body.load_map(name)
    if "tpose_axes" not in jm:
        return np.asarray(body.tpose_globals(name, skeleton), np.float64)
    g, bsk = body.tpose_globals(name), body.body_skeleton()
    to_body = {rig: b for b, rig in jm["joints"].items()}
    out = np.zeros((skeleton.num_joints, 4))
    done = np.zeros(skeleton.num_joints, bool)
    while not done.all():  # parents first, whatever the joint order
        for j in np.flatnonzero(~done):
            p = int(skeleton.parents[j])
            if p >= 0 and not done[p]:
                continue
            b = to_body.get(skeleton.names[j])
            out[j] = g[bsk.index(b)] if b is not None else (out[p] if p >= 0 else (1.0, 0.0, 0.0, 0.0))
            done[j] = True
    return out


def lower_on_rest_branch(lower: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Lower-body exp-maps ``(F, 24)`` -> the same rotations on the branch nearest ``ref`` (``(8, 3)``, the rest
    pose: ``body.rest_expmaps(body.LOWER)``; :func:`jaxgest.motion.body.nearest_branch`), float32."""
    v = body.nearest_branch(np.asarray(lower).reshape(len(lower), len(body.LOWER), 3), ref)
    return v.reshape(len(lower), -1).astype(np.float32)


def mirror_motion(motion: Motion) -> Motion:
    """``motion`` mirrored about the sagittal plane in the representation of the originals.

    :func:`jaxgest.motion.kinematics.mirror` with the rig's T-pose (:func:`rig_tpose`) as the symmetric
    reference: world positions are the reflected originals' (L/R swapped), and the mirrored local rotations
    are distributed like the originals' (the T-pose mirrors onto itself). Without the T-pose the Bandai-Namco
    shoulders, arms and legs of a mirrored clip would sit ~180 deg from any original's.
    """
    return kinematics.mirror(motion, tpose=rig_tpose(motion.skeleton))


def prepare_clips(clips: Sequence, cfg: Config) -> BodyData:
    """Dataset clips (``Clip`` or ``Motion``) -> :class:`BodyData` at ``cfg.model.fps`` with mirrored copies."""
    if not len(clips):
        raise DataError("TGST data: no clips")
    up, lo, mup, mlo, names, contents = [], [], [], [], [], []
    # the lower body only: a decoder target, never an input
    rest = body.rest_expmaps(body.LOWER) if cfg.train.autoencoder.expmap_branch == "rest" else None
    for i, c in enumerate(clips):
        motion = c.motion if isinstance(c, datasets.Clip) else c
        name = str(c.path) if isinstance(c, datasets.Clip) else (motion.name or f"clip {i}")
        contents.append(c.content if isinstance(c, datasets.Clip) else name)
        u, l = motion_to_arrays(motion, cfg.model.fps)
        mu, ml = motion_to_arrays(mirror_motion(motion), cfg.model.fps)
        if rest is not None:
            l, ml = lower_on_rest_branch(l, rest), lower_on_rest_branch(ml, rest)
        up.append(u), lo.append(l), mup.append(mu), mlo.append(ml), names.append(name)
    return BodyData(up, lo, mup, mlo, names, float(cfg.model.fps), contents)


def channel_stats(data: BodyData, min_std: float = 1e-2) -> dict:
    """Per-channel mean and std (floored at ``min_std``) of every frame of the original and mirrored clips.

    ``{"upper_mean", "upper_std"}`` (39,) and ``{"lower_mean", "lower_std"}`` (24,) float32: the frozen
    parameters of a standardising autoencoder (``AutoencoderConfig.standardize``).
    """
    out = {}
    for part in ("upper", "lower"):
        x = np.concatenate(getattr(data, part) + getattr(data, f"mirrored_{part}"), axis=0).astype(np.float64)
        out[f"{part}_mean"] = x.mean(0).astype(np.float32)
        out[f"{part}_std"] = np.maximum(x.std(0), min_std).astype(np.float32)
    return out


def load_body_data(data_dir, cfg: Config, progress: bool = False) -> BodyData:
    """:func:`prepare_clips` of every clip in ``data_dir`` (any layout of ``load_folder``)."""
    return prepare_clips(datasets.load_folder(data_dir, progress=progress), cfg)


def _fit(window: int, lengths: np.ndarray, names: Sequence[str], multiple: int, min_frames: int,
         min_clips: int, what: str) -> int:
    longest = int(np.argmax(lengths))
    if lengths[longest] < min_frames:
        raise DataError(f"no clip is long enough for a {min_frames}-frame {what} window: the longest, "
                        f"{names[longest]}, has {lengths[longest]} frames at the model rate")
    usable = np.sort(lengths[lengths >= min_frames])
    if len(usable) < min_clips:
        raise DataError(f"{what} training needs at least {min_clips} clips of >= {min_frames} frames at the "
                        f"model rate; found {len(usable)} (longest: {names[longest]})")
    median = int(usable[(len(usable) - 1) // 2])
    fitted = max(min_frames, median // multiple * multiple)
    return int(min(window, fitted))


def fit_windows(cfg: Config, data: BodyData) -> Config:
    """``cfg`` with both training windows (``cfg.train.*.window``) scaled to the data (module docstring).

    Windows stay multiples of 16 frames (the encoder's x4 reduction and the token stride) and never grow.
    """
    lengths, m = data.lengths, cfg.model.frame_multiple
    ae = _fit(cfg.train.autoencoder.window, lengths, data.names, m, cfg.model.min_frames, 1, "autoencoder")
    tr = _fit(cfg.train.transformer.window, lengths, data.names, m, cfg.model.min_frames, 2, "transformer")
    t = cfg.train
    return dataclasses.replace(cfg, train=dataclasses.replace(
        t, autoencoder=dataclasses.replace(t.autoencoder, window=ae),
        transformer=dataclasses.replace(t.transformer, window=tr)))


def _rng(seed: int, stage: int, step: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), int(stage), int(step)])


def ae_batch(data: BodyData, cfg: Config, seed: int, step: int) -> dict:
    """``{"upper": (B, W, 39), "lower": (B, W, 24)}`` float32 windows of original and mirrored clips.

    ``cfg.train.autoencoder.mirror=False`` leaves the mirrored clips out. ``cfg.train.autoencoder.sampling``
    ``"windows"``: uniform over all valid (clip, start) pairs of both sets;
    ``"content"``: every content label gets the same share of the windows (uniform over the valid windows of
    its clips), so a few long or numerous contents (Bandai-Namco: 105 of 144 training clips are locomotion)
    do not drown the others. B = ``cfg.train.autoencoder.batch_size``, W = ``cfg.train.autoencoder.window``.
    """
    rng = _rng(seed, AE_STAGE, step)
    copies = 2 if cfg.train.autoencoder.mirror else 1  # ae_mirror=False: the original clips only
    uppers = (data.upper + data.mirrored_upper)[:copies * len(data.upper)]
    lowers = (data.lower + data.mirrored_lower)[:copies * len(data.lower)]
    groups = None
    if cfg.train.autoencoder.sampling == "content":
        groups = list(data.contents or data.names) * copies
    t = cfg.train.autoencoder
    w = sample_windows_idx(np.concatenate([data.lengths] * copies), t.window, t.batch_size, rng,
                           list(data.names) * copies, groups=groups)
    up = np.stack([uppers[i][s:s + cfg.train.autoencoder.window] for i, s in w])
    lo = np.stack([lowers[i][s:s + cfg.train.autoencoder.window] for i, s in w])
    return {"upper": up, "lower": lo}


def sample_windows_idx(lengths: np.ndarray, length: int, batch: int, rng: np.random.Generator,
                       names: Sequence[str], groups: Optional[Sequence[str]] = None) -> list[tuple[int, int]]:
    """``batch`` (clip, start) pairs uniform over the valid windows (DataError naming the longest clip).

    groups: a label per clip; then every label with a valid window gets the same probability, spread
    uniformly over its valid windows.
    """
    valid = np.maximum(lengths - length + 1, 0)
    if valid.sum() == 0:
        hi = int(np.argmax(lengths))
        raise DataError(f"no clip is long enough for a {length}-frame window: the longest, {names[hi]}, has "
                        f"{lengths[hi]} frames at the model rate")
    p = valid / valid.sum()
    if groups is not None:
        labels = np.asarray([str(g) for g in groups])
        p = np.zeros(len(lengths))
        live = [g for g in dict.fromkeys(labels) if valid[labels == g].sum() > 0]
        for g in live:
            m = labels == g
            p[m] = valid[m] / valid[m].sum() / len(live)
    index = rng.choice(len(lengths), size=batch, p=p)
    return [(int(i), int(rng.integers(0, valid[i]))) for i in index]


def append_mirror(upper: np.ndarray, mirrored: np.ndarray, transition: int) -> np.ndarray:
    """A clip ``(F, C)`` of exp-maps followed by its mirror ``(F', C)``, blended over ``transition`` frames.

    As the authors' ``MocapClip.append(mirrored, transit=True, period=30)`` (and
    :func:`jaxgest.motion.kinematics.append_motion`): the clip's last ``transition`` frames move toward the
    mirror's first ones (per-joint slerp, weight k / transition), then the mirror continues from its frame
    ``transition``: ``F + F' - transition`` frames.
    References: the authors' dataset/mocap.py (``add_mirror_motion``, ``append``).
    """
    a, b = np.array(upper, dtype=np.float32), np.asarray(mirrored, dtype=np.float32)
    n = max(0, min(int(transition), len(a), len(b)))
    if n:
        qa = R.expmap_to_quat(a[-n:].reshape(n, -1, 3).astype(np.float64))
        qb = R.expmap_to_quat(b[:n].reshape(n, -1, 3).astype(np.float64))
        t = np.broadcast_to((np.arange(n) / n)[:, None], qa.shape[:2])
        a[-n:] = R.quat_to_expmap(R.quat_slerp(qa, qb, t)).reshape(n, -1).astype(np.float32)
    return np.concatenate([a, b[n:]])


def style_token_count(frames, cfg: Config):
    """Gesture tokens lying wholly in the first ``frames`` frames of a clip (token m covers latent frames
    m*h .. m*h + w - 1): the real tokens of a style clip padded at the end. Works on ints and arrays."""
    m = cfg.model
    latent = np.asarray(frames) // m.autoencoder.time_reduction
    return np.where(latent < m.token_width, 0, (latent - m.token_width) // m.token_stride + 1)


def transformer_batch(data: BodyData, cfg: Config, seed: int, step: int,
                      mirror_prob: float = 0.5) -> dict:
    """``{"content": (B, W, 39), "style": (B, Fs, 39)}`` of unaligned pairs of different clips.

    ``cfg.train.transformer.style_tokens="window"``: content and style clips are drawn uniformly among
    clips of at least W = ``cfg.train.transformer.window`` frames (two different clips per pair), each
    window starts uniformly at random, and the style window (Fs = W) is taken from the mirrored clip with
    probability ``mirror_prob`` (style augmentation, §4.1). ``"clip_and_mirror"``: see
    :func:`clip_and_mirror_batch` (adds ``"style_valid"``).
    References: Kuriyama et al. 2022, §3.5 ("no behavioral synchronization or time alignment").
    """
    if cfg.train.transformer.style_tokens == "clip_and_mirror":
        return clip_and_mirror_batch(data, cfg, seed, step)
    rng = _rng(seed, TRANSFORMER_STAGE, step)
    w, b = cfg.train.transformer.window, cfg.train.transformer.batch_size
    usable = _usable_contents(data, w)
    content, style = [], []
    for _ in range(b):
        ci, si = rng.choice(usable, size=2, replace=False)
        cs = int(rng.integers(0, data.lengths[ci] - w + 1))
        ss = int(rng.integers(0, data.lengths[si] - w + 1))
        mirrored = bool(rng.random() < mirror_prob)
        content.append(data.upper[ci][cs:cs + w])
        style.append((data.mirrored_upper if mirrored else data.upper)[si][ss:ss + w])
    return {"content": np.stack(content), "style": np.stack(style)}


def _usable_contents(data: BodyData, w: int) -> np.ndarray:
    usable = np.flatnonzero(data.lengths >= w)
    if len(usable) < 2:
        hi = int(np.argmax(data.lengths))
        raise DataError(f"content/style pairs need two clips of >= {w} frames; the longest, {data.names[hi]}, "
                        f"has {data.lengths[hi]} frames at the model rate")
    return usable


def clip_and_mirror_batch(data: BodyData, cfg: Config, seed: int, step: int) -> dict:
    """Content windows and whole style clips with their mirrors: the authors' transformer data.

    Returns ``{"content": (B, W, 39), "style": (B, Fs, 39), "style_valid": (B, Ns) bool}``. Per pair: a
    content window of W = ``cfg.train.transformer.window`` frames of a clip drawn uniformly among the clips
    at least that long; a style clip drawn uniformly among the other clips, taken whole (a random window of
    ``style_max_frames`` frames if longer) and followed by its mirror (:func:`append_mirror`, blended over
    ``style_transition_seconds``): one token set holding both, as the authors' trainer builds it
    (``setup_style_tokens``: ``add_mirror_motion`` then the whole clip encoded). The style arrays are
    edge-padded at the end to Fs = the batch's longest, rounded up to a length bucket
    (:func:`jaxgest.tgst.batched.bucket_length`, ratio ``style_bucket``: few shapes, few compilations);
    ``style_valid[i, m]`` marks the tokens wholly inside pair i's real frames (:func:`style_token_count`).
    The authors draw one style clip per batch; here every pair draws its own.
    References: the authors' gsxf.py (``train_dataloader``, ``setup_style_tokens``, ``forward``).
    """
    from jaxgest.tgst.batched import bucket_length  # light module; avoids importing the model at load time

    t = cfg.train.transformer
    rng = _rng(seed, TRANSFORMER_STAGE, step)
    w, b = t.window, t.batch_size
    usable = _usable_contents(data, w)
    transition = int(round(t.style_transition_seconds * data.fps))
    content, style = [], []
    for _ in range(b):
        ci = int(rng.choice(usable))
        si = int(rng.integers(0, len(data.lengths) - 1))
        si += si >= ci  # any other clip
        cs = int(rng.integers(0, data.lengths[ci] - w + 1))
        content.append(data.upper[ci][cs:cs + w])
        n = int(data.lengths[si])
        cap = n if not t.style_max_frames else min(n, int(t.style_max_frames))
        ss = int(rng.integers(0, n - cap + 1))
        style.append(append_mirror(data.upper[si][ss:ss + cap], data.mirrored_upper[si][ss:ss + cap], transition))
    frames = np.array([len(x) for x in style])
    m = cfg.model.frame_multiple
    fs = -(-bucket_length(int(frames.max()), t.style_bucket, multiple=m) // m) * m
    padded = np.stack([np.pad(x, ((0, fs - len(x)), (0, 0)), mode="edge") for x in style])
    ns = int(style_token_count(fs, cfg))
    valid = np.arange(ns)[None, :] < style_token_count(frames, cfg)[:, None]
    return {"content": np.stack(content), "style": padded, "style_valid": valid}


def describe(data: BodyData, cfg: Optional[Config] = None) -> dict:
    """JSON-friendly summary: clip count, frames, lengths and (with ``cfg``) the windows used."""
    lengths = data.lengths
    out = {"clips": len(lengths), "frames": int(lengths.sum()), "fps": data.fps,
           "shortest": int(lengths.min()), "longest": int(lengths.max()), "median": float(np.median(lengths))}
    if cfg is not None:
        out.update(ae_window=cfg.train.autoencoder.window, transformer_window=cfg.train.transformer.window,
                   ae_window_clips=int((lengths >= cfg.train.autoencoder.window).sum()),
                   transformer_window_clips=int((lengths >= cfg.train.transformer.window).sum()))
    return out

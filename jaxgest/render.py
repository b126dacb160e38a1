"""Stick-figure stills and animations of motions (matplotlib Agg + Pillow GIF writing; no ffmpeg).

The figure is projected orthographically onto the image plane of a fixed camera in front of the
character (which faces +Z) turned by a slight 3/4 angle and raised a little. The camera framing is taken
from the whole clip (every frame of every panel), so it never moves and all panels share it. Several
motions render side by side with a title each (e.g. content / style / result).

GIF frames are blitted (the static background is drawn once) and written with Pillow exactly as
matplotlib's ``PillowWriter`` writes them, so a 10 s clip takes about a second or two.
"""

from __future__ import annotations

import pathlib
from typing import Optional, Sequence, Union

import numpy as np

from jaxgest.runtime.errors import DataError
from jaxgest.runtime.io import atomic_output, check_output_path
from jaxgest.motion.skeleton import Motion

YAW_DEG = 25.0  # 3/4 view: the camera sits front-right of the character
ELEV_DEG = 10.0  # and slightly above
PANEL_INCHES = (2.6, 3.6)
DPI = 80
COLORS = {"L": "#1f5fbf", "R": "#c8322d", "C": "#333333"}


def _side(name: str) -> str:
    n = name.lower()
    if n.endswith(("_l", ".l", "left")) or n.startswith(("left", "l_")) or "left" in n:
        return "L"
    if n.endswith(("_r", ".r", "right")) or n.startswith(("right", "r_")) or "right" in n:
        return "R"
    return "C"


def project(points: np.ndarray, up_axis: int = 1, yaw_deg: float = YAW_DEG, elev_deg: float = ELEV_DEG):
    """Orthographic camera projection of world points (..., 3) -> image-plane (..., 2) (x right, y up)."""
    p = np.asarray(points, dtype=np.float64)
    if up_axis != 1:  # bring the up axis to Y, keeping a right-handed frame
        p = np.roll(p, 1 - up_axis, axis=-1)
    a, e = np.radians(yaw_deg), np.radians(elev_deg)
    x = p[..., 0] * np.cos(a) + p[..., 2] * np.sin(a)
    z = -p[..., 0] * np.sin(a) + p[..., 2] * np.cos(a)
    y = p[..., 1] * np.cos(e) - z * np.sin(e)
    return np.stack([x, y], axis=-1)


def _as_list(motions) -> list:
    if isinstance(motions, Motion):
        return [motions]
    motions = list(motions)
    if not motions or not all(isinstance(m, Motion) for m in motions):
        raise DataError("render: expected one Motion or a non-empty list of Motions")
    return motions


def _positions(m: Motion) -> np.ndarray:
    from jaxgest.motion.kinematics import forward_kinematics

    pos = np.asarray(forward_kinematics(m), dtype=np.float64)
    if not np.all(np.isfinite(pos)):
        raise DataError(f"{m.name or 'motion'}: non-finite joint positions, cannot render")
    return pos


def _limits(projected: list, aspect: float):
    allp = np.concatenate([p.reshape(-1, 2) for p in projected], axis=0)
    lo, hi = allp.min(0), allp.max(0)
    lo[1] = min(lo[1], 0.0)
    size = np.maximum(hi - lo, 1e-6)
    pad = 0.08 * size.max()
    lo, hi = lo - pad, hi + pad
    w, h = hi - lo
    if w / h < aspect:  # widen to the panel's aspect ratio so the figure is not distorted
        c = (lo[0] + hi[0]) / 2
        lo[0], hi[0] = c - h * aspect / 2, c + h * aspect / 2
    else:
        c = (lo[1] + hi[1]) / 2
        lo[1], hi[1] = c - w / aspect / 2, c + w / aspect / 2
    return (lo[0], hi[0]), (lo[1], hi[1])


class _Figure:
    """Panels of stick figures sharing one camera."""

    def __init__(self, motions, titles, yaw_deg=YAW_DEG):
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        from matplotlib.collections import LineCollection

        self.motions = motions
        self.proj = [project(_positions(m), m.skeleton.up_axis, yaw_deg) for m in motions]
        n = len(motions)
        self.fig, axes = plt.subplots(1, n, figsize=(PANEL_INCHES[0] * n, PANEL_INCHES[1]), dpi=DPI, squeeze=False)
        self.axes = axes[0]
        xlim, ylim = _limits(self.proj, PANEL_INCHES[0] / (PANEL_INCHES[1] - 0.35))
        allp = np.concatenate([p.reshape(-1, 2) for p in self.proj])
        cx, half = allp[:, 0].mean(), 0.3 * (xlim[1] - xlim[0])
        floor = project(np.array([[cx - half, 0, -25], [cx + half, 0, -25], [cx + half, 0, 35], [cx - half, 0, 35]]),
                        1, yaw_deg)
        self.bones, self.dots, self.heads = [], [], []
        for k, (ax, m) in enumerate(zip(self.axes, motions)):
            sk = m.skeleton
            ax.set_xlim(*xlim)
            ax.set_ylim(*ylim)
            ax.set_aspect("equal")
            ax.axis("off")
            ax.fill(floor[:, 0], floor[:, 1], color="#e6e6e6", zorder=0)
            if titles is not None:
                ax.set_title(titles[k], fontsize=9)
            pairs = [(int(p), j) for j, p in enumerate(sk.parents) if p >= 0]
            colors = [COLORS[_side(sk.names[j])] for _, j in pairs]
            lc = LineCollection([], colors=colors, linewidths=2.2, capstyle="round", zorder=2)
            ax.add_collection(lc)
            self.bones.append((lc, np.array(pairs, dtype=int).reshape(-1, 2)))
            (dots,) = ax.plot([], [], "o", ms=2.5, color="#222222", zorder=3)
            self.dots.append(dots)
            head = [j for j, nm in enumerate(sk.names) if nm.lower() == "head"]
            if head:
                (h,) = ax.plot([], [], "o", ms=9, mfc="white", mec="#333333", mew=1.5, zorder=4)
                self.heads.append((h, head[0]))
            else:
                self.heads.append(None)
        self.fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.9, wspace=0.02)

    def draw(self, frames: Sequence[int]):
        for k, f in enumerate(frames):
            p = self.proj[k][f]
            lc, pairs = self.bones[k]
            lc.set_segments(np.stack([p[pairs[:, 0]], p[pairs[:, 1]]], axis=1) if len(pairs) else [])
            self.dots[k].set_data(p[:, 0], p[:, 1])
            if self.heads[k] is not None:
                h, j = self.heads[k]
                h.set_data([p[j, 0]], [p[j, 1]])

    def animated(self):
        for k in range(len(self.motions)):
            yield self.bones[k][0]
            yield self.dots[k]
            if self.heads[k] is not None:
                yield self.heads[k][0]

    def frames_rgb(self, frame_lists):
        """Blitted rendering: the static background (floor, titles) is drawn once, then only the figure
        artists per frame. Yields (H, W, 3) uint8 images."""
        canvas = self.fig.canvas
        for a in self.animated():
            a.set_animated(True)
        canvas.draw()
        background = canvas.copy_from_bbox(self.fig.bbox)
        for frames in frame_lists:
            canvas.restore_region(background)
            self.draw(frames)
            for k, a in enumerate(self.animated()):
                a.axes.draw_artist(a)
            yield np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def close(self):
        import matplotlib.pyplot as plt

        plt.close(self.fig)


def _titles(titles, n):
    if titles is None:
        return None
    titles = [str(t) for t in titles]
    if len(titles) != n:
        raise DataError(f"render: {len(titles)} titles for {n} motions")
    return titles


def render_gif(
    motions: Union[Motion, Sequence[Motion]],
    out_path,
    titles: Optional[Sequence[str]] = None,
    fps: Optional[float] = None,
    max_seconds: Optional[float] = None,
    yaw_deg: float = YAW_DEG,
) -> pathlib.Path:
    """Animated GIF of one motion or several side by side.

    Args:
      motions: a Motion or a list of Motions (one panel each; shorter clips hold their last frame).
      out_path: the .gif to write (atomically, :func:`jaxgest.runtime.io.atomic_output`).
      titles: one title per panel, or None.
      fps: GIF frame rate; default ``min(motion fps, 20)``, frames are subsampled in time.
      max_seconds: render at most this many seconds.
      yaw_deg: camera angle about the vertical axis (0 = straight front, 90 = the character's left side).
    Raises:
      DataError: the output directory does not exist, titles do not match, or positions are not finite.
    """
    from PIL import Image

    motions = _as_list(motions)
    out = check_output_path(out_path)
    titles = _titles(titles, len(motions))
    src_fps = min(m.fps for m in motions)
    fps = float(min(src_fps, 20.0) if fps is None else fps)
    if fps <= 0:
        raise DataError(f"render: fps must be positive, got {fps}")
    duration = max(m.duration for m in motions)
    if max_seconds is not None:
        duration = min(duration, float(max_seconds))
    n_out = max(1, int(np.floor(duration * fps + 1e-9)))
    fig = _Figure(motions, titles, yaw_deg)
    try:
        times = np.arange(n_out) / fps
        frame_lists = ([min(int(round(t * m.fps)), m.num_frames - 1) for m in motions] for t in times)
        images = [Image.fromarray(rgb).convert("P", palette=Image.Palette.ADAPTIVE, colors=32)
                  for rgb in fig.frames_rgb(frame_lists)]
        # what matplotlib's PillowWriter does, without re-drawing the static parts for every frame
        with atomic_output(out) as tmp:
            images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                           duration=int(round(1000 / fps)), loop=0)
    finally:
        fig.close()
    return out


def render_png(
    motions: Union[Motion, Sequence[Motion]],
    out_path,
    frame: Optional[int] = None,
    titles: Optional[Sequence[str]] = None,
    yaw_deg: float = YAW_DEG,
) -> pathlib.Path:
    """A still PNG of ``frame`` (default: the middle frame) of one or several motions side by side."""
    motions = _as_list(motions)
    out = check_output_path(out_path)
    titles = _titles(titles, len(motions))
    fig = _Figure(motions, titles, yaw_deg)
    try:
        frames = []
        for m in motions:
            f = m.num_frames // 2 if frame is None else int(frame)
            if not -m.num_frames <= f < m.num_frames:
                raise DataError(f"render: frame {frame} outside {m.name or 'motion'} ({m.num_frames} frames)")
            frames.append(f % m.num_frames)
        fig.draw(frames)
        with atomic_output(out) as tmp:
            fig.fig.savefig(tmp, dpi=DPI, format="png")
    finally:
        fig.close()
    return out

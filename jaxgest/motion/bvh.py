"""Strict BVH reader and writer (SPEC §2).

``load(path) -> Motion`` and ``save(motion, path)``. The reader is strict: any problem raises
:class:`BVHError` with ``"{file}:{line}: {reason}"``. Accepted: any Euler order per joint (a permutation of
X/Y/Z rotation channels, position channels anywhere in the list), 3 or 6 channels on any joint, End Sites
(kept for writing, not joints), joint names with colons or any non-space characters, a frame time in any
float notation, CRLF line endings, tabs or spaces.

The frame rate is ``1 / frame_time`` snapped to the nearest integer when within 0.01% (files round the
frame time, e.g. ``0.0333333`` or ``3.33333e-02`` for 30 fps).

Rotations become local unit quaternions (w, x, y, z) in float64 (``R = R_a0 R_a1 R_a2`` in channel order);
translations are the position channels where a joint has them, otherwise its rest offset. The writer
restores each joint's channel layout, so a saved file reloads with the same hierarchy, rotations within
1e-5 rad and world positions within 1e-3 cm.
"""

from __future__ import annotations

import pathlib
import re

import numpy as np

from jaxgest.errors import DataError
from jaxgest.io import write_text_atomic
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
KNOWN_CHANNELS = POSITION_CHANNELS + ROTATION_CHANNELS


class BVHError(DataError):
    """A malformed or unreadable BVH file; the message names the file, the line and the reason."""


class _Lines:
    """Tokenised lines with 1-based line numbers, skipping blank lines."""

    def __init__(self, text: str, name: str):
        self.name = name
        self.items = []
        for i, raw in enumerate(text.splitlines(), start=1):
            s = raw.strip()
            if s:
                self.items.append((i, s))
        self.pos = 0

    def error(self, line, reason):
        loc = f"{self.name}:{line}" if line is not None else self.name
        return BVHError(f"{loc}: {reason}")

    def peek(self):
        return self.items[self.pos] if self.pos < len(self.items) else (None, None)

    def next(self, what: str):
        if self.pos >= len(self.items):
            last = self.items[-1][0] if self.items else None
            raise self.error(last, f"unexpected end of file, expected {what}")
        item = self.items[self.pos]
        self.pos += 1
        return item

    def last_line(self):
        return self.items[-1][0] if self.items else None


def _float(lines: _Lines, line: int, token: str, what: str) -> float:
    try:
        v = float(token)
    except ValueError:
        raise lines.error(line, f"cannot parse {what} {token!r} as a number") from None
    if not np.isfinite(v):
        raise lines.error(line, f"non-finite {what} {token!r}")
    return v


def _parse_offset(lines: _Lines) -> np.ndarray:
    ln, s = lines.next("OFFSET")
    parts = s.split()
    if parts[0].upper() != "OFFSET":
        raise lines.error(ln, f"expected OFFSET, found {parts[0]!r}")
    if len(parts) != 4:
        raise lines.error(ln, f"OFFSET needs 3 numbers, found {len(parts) - 1}")
    return np.array([_float(lines, ln, p, "OFFSET value") for p in parts[1:]])


def _parse_channels(lines: _Lines, joint: str) -> tuple:
    ln, s = lines.next("CHANNELS")
    parts = s.split()
    if parts[0].upper() != "CHANNELS":
        raise lines.error(ln, f"joint {joint!r} has no CHANNELS line (found {parts[0]!r})")
    if len(parts) < 2:
        raise lines.error(ln, "CHANNELS without a count")
    try:
        n = int(parts[1])
    except ValueError:
        raise lines.error(ln, f"cannot parse channel count {parts[1]!r}") from None
    names = tuple(parts[2:])
    if n not in (3, 6):
        raise lines.error(ln, f"joint {joint!r} has {n} channels; only 3 or 6 are supported")
    if len(names) != n:
        raise lines.error(ln, f"CHANNELS says {n} but lists {len(names)} names")
    for c in names:
        if c not in KNOWN_CHANNELS:
            raise lines.error(ln, f"unknown channel {c!r} on joint {joint!r}")
    rot = [c for c in names if c in ROTATION_CHANNELS]
    if len(rot) != 3 or len(set(rot)) != 3:
        raise lines.error(ln, f"joint {joint!r} needs one X, Y and Z rotation channel, got {' '.join(names)}")
    pos = [c for c in names if c in POSITION_CHANNELS]
    if len(pos) not in (0, 3) or len(set(pos)) != len(pos):
        raise lines.error(ln, f"joint {joint!r} needs all three position channels or none")
    return names


def _expect_brace(lines: _Lines, brace: str):
    ln, s = lines.next(f"'{brace}'")
    if s != brace:
        raise lines.error(ln, f"expected '{brace}', found {s.split()[0]!r} (unbalanced braces?)")


def _parse_hierarchy(lines: _Lines):
    names, parents, offsets, channels, end_sites = [], [], [], [], {}
    ln, s = lines.next("HIERARCHY")
    if s.upper() != "HIERARCHY":
        raise lines.error(ln, f"expected HIERARCHY, found {s.split()[0]!r}")
    ln, s = lines.next("ROOT")
    parts = s.split(None, 1)
    if parts[0].upper() != "ROOT" or len(parts) < 2:
        raise lines.error(ln, "expected 'ROOT <name>'")

    def parse_joint(name: str, parent: int, line: int):
        if name in names:
            raise lines.error(line, f"duplicate joint name {name!r}")
        idx = len(names)
        names.append(name)
        parents.append(parent)
        _expect_brace(lines, "{")
        offsets.append(_parse_offset(lines))
        channels.append(_parse_channels(lines, name))
        while True:
            ln2, s2 = lines.next("'}' or JOINT")
            head = s2.split(None, 1)
            key = head[0].upper()
            if s2 == "}":
                return
            if key == "JOINT":
                if len(head) < 2:
                    raise lines.error(ln2, "JOINT without a name")
                parse_joint(head[1].strip(), idx, ln2)
            elif key == "END":
                if idx in end_sites:
                    raise lines.error(ln2, f"joint {name!r} has two End Sites")
                _expect_brace(lines, "{")
                end_sites[idx] = _parse_offset(lines)
                _expect_brace(lines, "}")
            elif key == "MOTION":
                raise lines.error(ln2, "MOTION before the hierarchy was closed (unbalanced braces)")
            else:
                raise lines.error(ln2, f"unexpected {head[0]!r} inside joint {name!r}")

    parse_joint(parts[1].strip(), -1, ln)
    return names, parents, offsets, channels, end_sites


def _parse_motion(lines: _Lines, num_channels: int):
    ln, s = lines.next("MOTION")
    if s.upper() != "MOTION":
        if s == "}":
            raise lines.error(ln, "unbalanced braces: '}' after the root joint was closed")
        raise lines.error(ln, f"expected MOTION, found {s.split()[0]!r}")
    ln, s = lines.next("Frames:")
    m = re.fullmatch(r"Frames:\s*(\S+)", s, flags=re.IGNORECASE)
    if not m:
        raise lines.error(ln, "expected 'Frames: <count>'")
    try:
        frames = int(m.group(1))
    except ValueError:
        raise lines.error(ln, f"cannot parse frame count {m.group(1)!r}") from None
    if frames <= 0:
        raise lines.error(ln, f"the file has {frames} frames; at least one is needed")
    ln, s = lines.next("Frame Time:")
    m = re.fullmatch(r"Frame\s+Time:\s*(\S+)", s, flags=re.IGNORECASE)
    if not m:
        raise lines.error(ln, "expected 'Frame Time: <seconds>'")
    frame_time = _float(lines, ln, m.group(1), "frame time")
    if frame_time <= 0:
        raise lines.error(ln, f"frame time must be positive, got {m.group(1)}")
    rows = lines.items[lines.pos :]
    if len(rows) != frames:
        at = rows[frames][0] if len(rows) > frames else lines.last_line()
        raise lines.error(at, f"'Frames: {frames}' but the file has {len(rows)} motion rows")
    data = np.empty((frames, num_channels), dtype=np.float64)
    for r, (rln, text) in enumerate(rows):
        parts = text.split()
        if len(parts) != num_channels:
            raise lines.error(rln, f"motion row has {len(parts)} values, expected {num_channels}")
        try:
            data[r] = np.array(parts, dtype=np.float64)
        except ValueError:
            bad = next(p for p in parts if not _is_float(p))
            raise lines.error(rln, f"cannot parse motion value {bad!r} as a number") from None
        if not np.all(np.isfinite(data[r])):
            raise lines.error(rln, "motion row contains NaN or inf")
    return frame_time, data


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def loads(text: str, name: str = "<string>") -> Motion:
    """Parse BVH text into a :class:`Motion` (see module docstring); errors name ``name``."""
    lines = _Lines(text, name)
    if not lines.items:
        raise BVHError(f"{name}: empty file")
    names, parents, offsets, channels, end_sites = _parse_hierarchy(lines)
    num_channels = sum(len(c) for c in channels)
    frame_time, data = _parse_motion(lines, num_channels)
    F, J = data.shape[0], len(names)
    offsets = np.stack(offsets)
    rotations = np.empty((F, J, 4))
    translations = np.broadcast_to(offsets, (F, J, 3)).copy()
    col = 0
    for j, chans in enumerate(channels):
        block = data[:, col : col + len(chans)]
        col += len(chans)
        rot_idx = [k for k, c in enumerate(chans) if c in ROTATION_CHANNELS]
        order = "".join(chans[k][0] for k in rot_idx)
        rotations[:, j] = R.euler_to_quat(block[:, rot_idx], order)
        pos_idx = [k for k, c in enumerate(chans) if c in POSITION_CHANNELS]
        if pos_idx:
            by_axis = {chans[k][0]: k for k in pos_idx}
            translations[:, j] = block[:, [by_axis["X"], by_axis["Y"], by_axis["Z"]]]
    skeleton = Skeleton(names=tuple(names), parents=np.array(parents), offsets=offsets, channels=tuple(channels),
                        end_sites=end_sites)
    return Motion(skeleton, rotations, translations, fps=fps_from_frame_time(frame_time), name=_stem(name))


def fps_from_frame_time(frame_time: float) -> float:
    """``1 / frame_time``, snapped to the nearest integer when within 0.01% (``0.0333333`` -> 30.0)."""
    fps = 1.0 / frame_time
    r = round(fps)
    return float(r) if r > 0 and abs(fps - r) <= 1e-4 * r else fps


def _stem(name: str) -> str:
    return pathlib.Path(name).stem if name and not name.startswith("<") else name


def load(path) -> Motion:
    """Read a BVH file strictly; raises :class:`BVHError` naming the file, line and reason."""
    path = pathlib.Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise BVHError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise BVHError(f"{path}: is a directory, not a BVH file") from None
    except OSError as e:
        raise BVHError(f"{path}: cannot read ({e.strerror or e})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        if b"\x00" in raw:
            raise BVHError(f"{path}: binary data, not a BVH text file") from None
        text = raw.decode("latin-1")
    return loads(text, name=str(path))


def _fmt(x: float) -> str:
    s = f"{x:.6f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def dumps(motion: Motion) -> str:
    """BVH text of ``motion`` with each joint's stored channel layout."""
    sk = motion.skeleton
    children = {j: [] for j in range(sk.num_joints)}
    for j, p in enumerate(sk.parents):
        if p >= 0:
            children[int(p)].append(j)
    out = ["HIERARCHY"]

    def write(j: int, depth: int):
        ind = "\t" * depth
        out.append(f"{ind}{'ROOT' if sk.parents[j] < 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {' '.join(_fmt(v) for v in sk.offsets[j])}")
        out.append(f"{ind}\tCHANNELS {len(sk.channels[j])} {' '.join(sk.channels[j])}")
        for c in children[j]:
            write(c, depth + 1)
        if j in sk.end_sites:
            out.append(f"{ind}\tEnd Site")
            out.append(f"{ind}\t{{")
            out.append(f"{ind}\t\tOFFSET {' '.join(_fmt(v) for v in np.asarray(sk.end_sites[j]))}")
            out.append(f"{ind}\t}}")
        out.append(f"{ind}}}")

    roots = [j for j in range(sk.num_joints) if sk.parents[j] < 0]
    if len(roots) != 1:
        raise BVHError(f"{motion.name or 'motion'}: a BVH file needs exactly one root joint, found {len(roots)}")
    order = []

    def dfs(j):
        order.append(j)
        for c in children[j]:
            dfs(c)

    dfs(roots[0])
    if order != list(range(sk.num_joints)):
        raise ValueError("BVH joints must be in depth-first order (parents before children, subtrees contiguous)")
    write(roots[0], 0)
    F = motion.num_frames
    if F < 1:
        raise BVHError(f"{motion.name or 'motion'}: cannot write a BVH with zero frames")
    if not (np.all(np.isfinite(motion.rotations)) and np.all(np.isfinite(motion.translations))):
        raise BVHError(f"{motion.name or 'motion'}: motion contains NaN or inf; refusing to write it")
    cols = []
    for j, chans in enumerate(sk.channels):
        rot = [c[0] for c in chans if c in ROTATION_CHANNELS]
        euler = R.quat_to_euler(motion.rotations[:, j], "".join(rot))
        by_axis = {"X": 0, "Y": 1, "Z": 2}
        rk = 0
        for c in chans:
            if c in ROTATION_CHANNELS:
                cols.append(euler[:, rk])
                rk += 1
            else:
                cols.append(motion.translations[:, j, by_axis[c[0]]])
    data = np.stack(cols, axis=1)
    out.append("MOTION")
    out.append(f"Frames: {F}")
    out.append(f"Frame Time: {1.0 / motion.fps:.10g}")
    text = "\n".join(out) + "\n"
    body = "\n".join(" ".join(_fmt(v) for v in row) for row in data)
    return text + body + "\n"


def save(motion: Motion, path) -> None:
    """Write ``motion`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = pathlib.Path(path)
    if not path.parent.is_dir():
        raise BVHError(f"{path}: output directory {path.parent} does not exist")
    write_text_atomic(path, dumps(motion))

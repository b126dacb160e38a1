"""Skeleton and Motion containers (docs/design.md §2).

These two frozen dataclasses are the contract every other module reads motion through.
Arrays are NumPy (float64 on load); model code converts to ``jnp`` at its boundary.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Optional

import numpy as np


@dataclasses.dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy.

    Attributes:
      names: joint names in file order (End Sites are not joints). Names keep colons.
      parents: (J,) int array, -1 for the root; ``parents[j] < j`` for every non-root joint.
      offsets: (J, 3) rest offsets in file units (cm for both datasets).
      channels: per joint, the tuple of BVH channel names in file order, e.g.
        ``("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")``. Kept so a
        saved file has the layout it was read with.
      end_sites: mapping joint index -> (3,) End Site offset, kept for writing.
      up_axis: index of the vertical axis (1 = Y-up for both datasets).
    """

    names: tuple
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple = ()
    end_sites: dict = dataclasses.field(default_factory=dict)
    up_axis: int = 1

    def __post_init__(self):
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "names", tuple(self.names))
        J = len(self.names)
        if parents.shape != (J,) or offsets.shape != (J, 3):
            raise ValueError(f"Skeleton: {J} names but parents {parents.shape}, offsets {offsets.shape}")
        if not self.channels:
            default = (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),) + (
                ("Zrotation", "Xrotation", "Yrotation"),
            ) * (J - 1)
            object.__setattr__(self, "channels", default)
        object.__setattr__(self, "channels", tuple(tuple(c) for c in self.channels))

    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of joint ``name``; raises KeyError naming the joint when absent."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"joint {name!r} not in skeleton") from None

    def signature(self) -> str:
        """A short stable string identifying the hierarchy (names + parents), stored with checkpoints."""
        import hashlib

        h = hashlib.sha1(("|".join(self.names) + "#" + ",".join(map(str, self.parents))).encode())
        return h.hexdigest()[:16]


@dataclasses.dataclass(frozen=True, eq=False)
class Motion:
    """An animation on a skeleton.

    Attributes:
      skeleton: the :class:`Skeleton`.
      rotations: (F, J, 4) local unit quaternions (w, x, y, z).
      translations: (F, J, 3) local joint translations (position channels where the file has them,
        otherwise the rest offset).
      fps: frames per second.
      name: optional clip name (file stem).
    """

    skeleton: Skeleton
    rotations: np.ndarray
    translations: np.ndarray
    fps: float
    name: Optional[str] = None

    def __post_init__(self):
        rot = np.asarray(self.rotations, dtype=np.float64)
        trans = np.asarray(self.translations, dtype=np.float64)
        object.__setattr__(self, "rotations", rot)
        object.__setattr__(self, "translations", trans)
        object.__setattr__(self, "fps", float(self.fps))
        J = self.skeleton.num_joints
        if rot.ndim != 3 or rot.shape[1:] != (J, 4):
            raise ValueError(f"Motion: rotations {rot.shape} do not match (F, {J}, 4)")
        if trans.shape != rot.shape[:2] + (3,):
            raise ValueError(f"Motion: translations {trans.shape} do not match (F, {J}, 3)")

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def duration(self) -> float:
        return self.num_frames / self.fps

    def replace(self, **kw) -> "Motion":
        return dataclasses.replace(self, **kw)


# ---------------------------------------------------------------------------------------------------
# Left/right pairs (data): (regex on a joint name, replacement giving its mirror partner). The first
# pattern that matches a name is used. Names keep namespace prefixes (``mixamorig:LeftArm``).

LR_PATTERNS: tuple = (
    (r"_L$", "_R"), (r"_R$", "_L"),            # Bandai-Namco: UpperArm_L
    (r"^Left", "Right"), (r"^Right", "Left"),  # ZEGGS / Mixamo: LeftArm
    (r"^left", "right"), (r"^right", "left"),
    (r"^L_", "R_"), (r"^R_", "L_"),
    (r"\.L$", ".R"), (r"\.R$", ".L"),        # Blender: upper_arm.L
    (r"(?<=:)Left", "Right"), (r"(?<=:)Right", "Left"),  # mixamorig:LeftArm
)


def mirror_partner(name: str) -> str:
    """The L/R counterpart of a joint name by :data:`LR_PATTERNS` (the name itself for central joints)."""
    for pat, rep in LR_PATTERNS:
        if re.search(pat, name):
            return re.sub(pat, rep, name, count=1)
    return name


def mirror_pairs(skeleton: Skeleton) -> np.ndarray:
    """Index permutation ``perm`` (J,) with ``perm[j]`` = index of joint j's mirror partner.

    Central joints map to themselves, and so does a side joint whose partner is missing from the rig.
    ``perm[perm] == arange(J)``.
    """
    idx = {n: i for i, n in enumerate(skeleton.names)}
    perm = np.array([idx.get(mirror_partner(n), i) for i, n in enumerate(skeleton.names)], dtype=np.int64)
    # A partner whose own partner is not this joint (odd naming) is not a pair: keep both in place.
    bad = perm[perm] != np.arange(len(perm))
    perm[bad] = np.flatnonzero(bad)
    return perm


def up_vector(skeleton: Skeleton) -> np.ndarray:
    """The unit vertical axis (3,) of the skeleton's world frame (``skeleton.up_axis``)."""
    u = np.zeros(3)
    u[skeleton.up_axis] = 1.0
    return u

"""Shared by the BVH tests and .ci/check_demo.py: an example file, two small helpers, and ``reference_fk``, an
independent reference parser + forward kinematics (plain text parsing and scipy rotations, no jaxgest code),
so agreement with it checks jaxgest's reader, Euler convention and writer independently of
jaxgest.motion.rotations."""

from __future__ import annotations

import pathlib

import numpy as np
from scipy.spatial.transform import Rotation

from jaxgest.motion import rotations as R  # quat_close and numpy_fk only; reference_fk uses none of jaxgest

VALID = """HIERARCHY
ROOT mixamorig:Hips
{
  OFFSET 0 90 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
  JOINT Leg
  {
    OFFSET 5 -10 0
    CHANNELS 6 Xrotation Yrotation Zrotation Xposition Yposition Zposition
    End Site
    {
      OFFSET 0 -40 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 3.33333e-02
1 90 2 10 20 30 5 -6 7 1 2 3 5 -10 0
1.5 91 2 11 21 31 5 -6 8 1 2 3 5 -10 0.5


"""


def write(tmp_path, text, name="clip.bvh"):
    p = tmp_path / name
    p.write_text(text)
    return p


def quat_close(a, b, tol):
    """Largest rotation angle (rad) of a^-1 b is below tol (sign of q ignored)."""
    return float(np.max(R.quat_angle(R.quat_mul(R.quat_inv(a), b)))) < tol


def reference_fk(path):
    """World positions (F, J, 3) of the joints (End Sites dropped) and (names, parents) of a BVH file."""
    lines = [s.strip() for s in pathlib.Path(path).read_text(encoding="utf-8").splitlines() if s.strip()]
    names, parents, offsets, chans, stack = [], [], [], [], []
    i = 0
    while lines[i].upper() != "MOTION":
        tok = lines[i].split()
        if tok[0] in ("ROOT", "JOINT", "End"):
            names.append(lines[i].split(None, 1)[1] if tok[0] != "End" else None)
            parents.append(stack[-1] if stack else -1)
        elif tok[0] == "{":
            stack.append(len(names) - 1)
        elif tok[0] == "}":
            stack.pop()
        elif tok[0] == "OFFSET":
            offsets.append([float(x) for x in tok[1:4]])
        elif tok[0] == "CHANNELS":
            chans.append((len(names) - 1, tok[2:]))
        i += 1
    data = np.loadtxt(lines[i + 3 :], ndmin=2)
    F, J = len(data), len(names)
    local_pos = np.broadcast_to(np.array(offsets), (F, J, 3)).copy()
    local_rot = [Rotation.identity(F)] * J
    col = 0
    for j, cs in chans:
        block = data[:, col : col + len(cs)]
        col += len(cs)
        rc = [k for k, c in enumerate(cs) if c.endswith("rotation")]
        local_rot[j] = Rotation.from_euler("".join(cs[k][0] for k in rc), block[:, rc], degrees=True)
        pc = {cs[k][0]: k for k, c in enumerate(cs) if c.endswith("position")}
        if pc:
            local_pos[:, j] = block[:, [pc["X"], pc["Y"], pc["Z"]]]
    world_rot, world_pos = [None] * J, np.zeros((F, J, 3))
    for j in range(J):
        p = parents[j]
        if p < 0:
            world_rot[j], world_pos[:, j] = local_rot[j], local_pos[:, j]
        else:
            world_rot[j] = world_rot[p] * local_rot[j]
            world_pos[:, j] = world_pos[:, p] + world_rot[p].apply(local_pos[:, j])
    keep = [j for j in range(J) if names[j] is not None]
    remap = {j: k for k, j in enumerate(keep)}
    return world_pos[:, keep], [names[j] for j in keep], [remap.get(parents[j], -1) for j in keep]


def numpy_fk(m):
    """World positions (F, J, 3): G_j = G_p q_j, p_j = p_p + G_p t_j."""
    F, J = m.rotations.shape[:2]
    grot, pos = np.zeros((F, J, 4)), np.zeros((F, J, 3))
    for j, p in enumerate(m.skeleton.parents):
        if p < 0:
            grot[:, j], pos[:, j] = m.rotations[:, j], m.translations[:, j]
        else:
            grot[:, j] = R.quat_mul(grot[:, p], m.rotations[:, j])
            pos[:, j] = pos[:, p] + R.quat_rotate(grot[:, p], m.translations[:, j])
    return pos

"""Strict BVH reader/writer: malformed inputs, notation, round trips, real files against an independent FK."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.motion import bvh
from jaxgest.motion import rotations as R
from jaxgest.motion.bvh import BVHError

Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

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


def test_valid_file_with_colon_name_and_exponent_frame_time(tmp_path):
    m = bvh.load(write(tmp_path, VALID))
    assert m.fps == 30.0
    assert m.skeleton.names == ("mixamorig:Hips", "Spine", "Leg")
    assert m.num_frames == 2
    np.testing.assert_allclose(m.translations[1, 0], [1.5, 91, 2])
    np.testing.assert_allclose(m.translations[1, 2], [5, -10, 0.5])  # position channels after rotations
    np.testing.assert_allclose(m.translations[0, 1], [0, 10, 0])  # rest offset where no position channels
    ref = Rotation.from_euler("ZXY", [10, 20, 30], degrees=True).as_quat()
    q = m.rotations[0, 0]
    assert min(np.abs(q - np.r_[ref[3], ref[:3]]).max(), np.abs(q + np.r_[ref[3], ref[:3]]).max()) < 1e-12
    assert set(m.skeleton.end_sites) == {1, 2}


def test_crlf_and_tabs_accepted(tmp_path):
    m = bvh.load(write(tmp_path, VALID.replace("\n", "\r\n").replace("  ", "\t")))
    assert m.num_frames == 2


def _line_of(text, needle):
    return next(i for i, s in enumerate(text.splitlines(), 1) if needle in s)


MALFORMED = [
    ("unbalanced brace", lambda t: t.replace("    End Site\n    {\n      OFFSET 0 5 0\n    }\n  }\n", "    End Site\n    {\n      OFFSET 0 5 0\n    }\n", 1), "unbalanced|expected"),
    ("unknown channel", lambda t: t.replace("Zrotation Yrotation Xrotation", "Zrotation Yrotation Wrotation"), "unknown channel"),
    ("channel count", lambda t: t.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), "channels"),
    ("row width", lambda t: t.replace("1 2 3 5 -10 0\n1.5", "1 2 3 5 -10\n1.5"), "expected 15"),
    ("frames mismatch", lambda t: t.replace("Frames: 2", "Frames: 3"), "Frames: 3"),
    ("zero frames", lambda t: t.split("MOTION")[0] + "MOTION\nFrames: 0\nFrame Time: 0.03\n", "0 frames"),
    ("nan", lambda t: t.replace("1.5 91", "nan 91"), "NaN|non-finite"),
    ("inf", lambda t: t.replace("1.5 91", "1.5 inf"), "NaN|non-finite"),
    ("frame time zero", lambda t: t.replace("3.33333e-02", "0"), "positive"),
    ("frame time negative", lambda t: t.replace("3.33333e-02", "-0.03"), "positive"),
    ("unparsable number", lambda t: t.replace("1.5 91", "1.5 9x1"), "9x1"),
    ("unparsable offset", lambda t: t.replace("OFFSET 0 90 0", "OFFSET 0 abc 0"), "abc"),
    ("missing motion", lambda t: t.split("MOTION")[0], "end of file|MOTION"),
    ("missing hierarchy", lambda t: t.replace("HIERARCHY\n", ""), "HIERARCHY"),
    ("no channels", lambda t: t.replace("    CHANNELS 3 Zrotation Yrotation Xrotation\n", ""), "CHANNELS"),
    ("duplicate name", lambda t: t.replace("JOINT Leg", "JOINT Spine"), "duplicate"),
]


@pytest.mark.parametrize("case,mutate,reason", MALFORMED, ids=[c[0] for c in MALFORMED])
def test_malformed_raises_bvherror_with_file_and_line(tmp_path, case, mutate, reason):
    text = mutate(VALID)
    assert text != VALID
    p = write(tmp_path, text, name="bad.bvh")
    with pytest.raises(BVHError, match=reason) as info:
        bvh.load(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}:"), msg
    assert "\n" not in msg


def test_error_line_numbers_point_at_the_problem(tmp_path):
    text = VALID.replace("1.5 91", "1.5 9x1")
    with pytest.raises(BVHError) as info:
        bvh.load(write(tmp_path, text))
    assert f":{_line_of(text, '9x1')}:" in str(info.value)
    text = VALID.replace("Wrotation", "").replace("Zrotation Yrotation Xrotation", "Zrotation Yrotation Qrotation")
    with pytest.raises(BVHError) as info:
        bvh.load(write(tmp_path, text))
    assert f":{_line_of(text, 'Qrotation')}:" in str(info.value)


def test_empty_missing_directory_binary(tmp_path):
    with pytest.raises(BVHError, match="empty file"):
        bvh.load(write(tmp_path, "\n\n"))
    with pytest.raises(BVHError, match="no such file"):
        bvh.load(tmp_path / "nope.bvh")
    with pytest.raises(BVHError, match="directory"):
        bvh.load(tmp_path)
    (tmp_path / "bin.bvh").write_bytes(b"\x00\xff\x00HIER")
    with pytest.raises(BVHError, match="binary"):
        bvh.load(tmp_path / "bin.bvh")


def test_save_into_missing_directory_is_clear(tmp_path):
    m = bvh.load(write(tmp_path, VALID))
    with pytest.raises(BVHError, match="does not exist"):
        bvh.save(m, tmp_path / "missing" / "out.bvh")
    assert not (tmp_path / "missing").exists()


# ----------------------------------------------------------------------------------------------------
# Independent reference: a plain parser + FK with scipy rotations (shares no code with jaxgest).


def reference_fk(path):
    lines = [s.strip() for s in pathlib.Path(path).read_text().splitlines() if s.strip()]
    names, parents, offsets, chans, stack = [], [], [], [], []
    i = 0
    while not lines[i].upper().startswith("MOTION"):
        tok = lines[i].split()
        if tok[0] in ("ROOT", "JOINT"):
            names.append(tok[1])
            parents.append(stack[-1] if stack else -1)
        elif tok[0] == "End":
            names.append(None)
            parents.append(stack[-1])
        elif tok[0] == "{":
            stack.append(len(names) - 1)
        elif tok[0] == "}":
            stack.pop()
        elif tok[0] == "OFFSET":
            offsets.append([float(x) for x in tok[1:4]])
        elif tok[0] == "CHANNELS":
            chans.append((len(names) - 1, tok[2:]))
        i += 1
    data = np.array([[float(x) for x in s.split()] for s in lines[i + 3 :]])
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
    return world_pos[:, keep], [names[j] for j in keep]


def numpy_fk(m):
    F, J = m.rotations.shape[:2]
    grot, pos = np.zeros((F, J, 4)), np.zeros((F, J, 3))
    for j, p in enumerate(m.skeleton.parents):
        if p < 0:
            grot[:, j], pos[:, j] = m.rotations[:, j], m.translations[:, j]
        else:
            grot[:, j] = R.quat_mul(grot[:, p], m.rotations[:, j])
            pos[:, j] = pos[:, p] + R.quat_rotate(grot[:, p], m.translations[:, j])
    return pos


def test_small_file_fk_matches_reference(tmp_path):
    p = write(tmp_path, VALID)
    ref, names = reference_fk(p)
    m = bvh.load(p)
    assert tuple(names) == m.skeleton.names
    np.testing.assert_allclose(numpy_fk(m), ref, atol=1e-9)


@st.composite
def random_motion(draw):
    J = draw(st.integers(1, 6))
    parents = [-1]
    for j in range(1, J):  # depth-first file order: the parent lies on the path from the root to j - 1
        path, a = [], j - 1
        while a >= 0:
            path.append(a)
            a = parents[a]
        parents.append(draw(st.sampled_from(path)))
    orders = [draw(st.sampled_from(["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])) for _ in range(J)]
    six = [True] + [draw(st.booleans()) for _ in range(J - 1)]
    seed = draw(st.integers(0, 2**31 - 1))
    F = draw(st.integers(1, 5))
    rng = np.random.default_rng(seed)
    chans = []
    for j in range(J):
        rot = tuple(f"{a}rotation" for a in orders[j])
        chans.append(("Xposition", "Yposition", "Zposition") + rot if six[j] else rot)
    from jaxgest.motion.skeleton import Motion, Skeleton

    offsets = rng.normal(scale=10, size=(J, 3))
    sk = Skeleton(names=tuple(f"j{j}:n" for j in range(J)), parents=np.array(parents), offsets=offsets,
                  channels=tuple(chans), end_sites={J - 1: np.array([0.0, 3.0, 0.0])})
    angles = rng.uniform(-179, 179, size=(F, J, 3))
    angles[..., 1] = rng.uniform(-89, 89, size=(F, J))
    rots = np.stack([R.euler_to_quat(angles[:, j], orders[j]) for j in range(J)], axis=1)
    trans = np.broadcast_to(offsets, (F, J, 3)).copy()
    trans[:, np.array(six)] += rng.normal(scale=5, size=(F, int(np.sum(six)), 3))
    return Motion(sk, rots, trans, fps=float(draw(st.sampled_from([24, 30, 60, 120]))))


@settings(max_examples=25, deadline=None)
@given(random_motion())
def test_save_load_round_trip_on_generated_skeletons(tmp_path_factory, m):
    p = tmp_path_factory.mktemp("rt") / "m.bvh"
    bvh.save(m, p)
    m2 = bvh.load(p)
    assert m2.skeleton.names == m.skeleton.names
    np.testing.assert_array_equal(m2.skeleton.parents, m.skeleton.parents)
    assert m2.skeleton.channels == m.skeleton.channels
    assert m2.fps == m.fps
    assert R.quat_angle(R.quat_mul(R.quat_inv(m.rotations), m2.rotations)).max() < 1e-5
    np.testing.assert_allclose(numpy_fk(m2), numpy_fk(m), atol=1e-3)
    ref, _ = reference_fk(p)
    np.testing.assert_allclose(ref, numpy_fk(m), atol=1e-3)


# ----------------------------------------------------------------------------------------------------
# Real data (skipped cleanly when ../shared is absent)


@pytest.mark.realdata
def test_every_bandai_file_loads_and_matches_reference_fk(bandai_dir, tmp_path):
    files = sorted(bandai_dir.glob("*.bvh"))
    assert len(files) == 174
    for k, f in enumerate(files):
        m = bvh.load(f)
        assert m.skeleton.num_joints == 22 and m.fps == 30.0
        header_frames = int(next(s for s in f.read_text().splitlines() if s.startswith("Frames:")).split()[1])
        assert m.num_frames == header_frames
        if k % 20 == 0:  # the independent parser is slow; every 20th file, plus the round trip
            ref, names = reference_fk(f)
            assert tuple(names) == m.skeleton.names
            np.testing.assert_allclose(numpy_fk(m), ref, atol=1e-2)
            out = tmp_path / f.name
            bvh.save(m, out)
            np.testing.assert_allclose(reference_fk(out)[0], ref, atol=1e-2)


@pytest.mark.realdata
def test_zeggs_file_loads_and_matches_reference_fk(zeggs_dir, tmp_path):
    f = zeggs_dir / "067_Speech_2_x_1_0.bvh"
    m = bvh.load(f)
    assert m.skeleton.num_joints == 75 and m.fps == 30.0
    ref, names = reference_fk(f)
    np.testing.assert_allclose(numpy_fk(m), ref, atol=1e-2)
    bvh.save(m, tmp_path / "z.bvh")
    np.testing.assert_allclose(reference_fk(tmp_path / "z.bvh")[0], ref, atol=1e-2)

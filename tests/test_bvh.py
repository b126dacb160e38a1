"""Strict BVH reader/writer: malformed inputs with file:line, notation, round trips, real files vs an independent FK.

The reference parser + FK below uses only NumPy and scipy (no jaxgest code), so agreement with it checks
the reader, the Euler convention and the writer independently of jaxgest.motion.rotations.
"""

from __future__ import annotations

import os
import pathlib
import re

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from jaxgest.errors import DataError
from jaxgest.motion import bvh
from jaxgest.motion import rotations as R
from jaxgest.motion.bvh import BVHError
from jaxgest.motion.skeleton import Motion, Skeleton

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


def quat_close(a, b, tol):
    """Largest rotation angle (rad) of a^-1 b is below tol (sign of q ignored)."""
    return float(np.max(R.quat_angle(R.quat_mul(R.quat_inv(a), b)))) < tol


# ----------------------------------------------------------------------------------------------------
# Valid files


def test_valid_file_with_colon_name_and_exponent_frame_time(tmp_path):
    m = bvh.load(write(tmp_path, VALID))
    assert round(m.fps) == 30 and isinstance(m.fps, float)
    assert m.skeleton.names == ("mixamorig:Hips", "Spine", "Leg")
    assert m.name == "clip" and m.num_frames == 2
    np.testing.assert_array_equal(m.skeleton.parents, [-1, 0, 0])
    np.testing.assert_allclose(m.skeleton.offsets, [[0, 90, 0], [0, 10, 0], [5, -10, 0]])
    np.testing.assert_allclose(m.translations[1, 0], [1.5, 91, 2])
    np.testing.assert_allclose(m.translations[1, 2], [5, -10, 0.5])  # position channels after rotations
    np.testing.assert_allclose(m.translations[:, 1], [[0, 10, 0]] * 2)  # rest offset: no position channels
    assert m.skeleton.channels[1] == ("Zrotation", "Yrotation", "Xrotation")
    for j, cols, order in [(0, [3, 4, 5], "ZXY"), (1, [6, 7, 8], "ZYX"), (2, [9, 10, 11], "XYZ")]:
        angles = np.array([[float(x) for x in row.split()] for row in VALID.split("\n")[-5:-3]])[:, cols]
        ref = Rotation.from_euler(order, angles, degrees=True).as_quat()[:, [3, 0, 1, 2]]
        assert quat_close(m.rotations[:, j], ref, 1e-12)
    assert set(m.skeleton.end_sites) == {1, 2}
    np.testing.assert_allclose(m.skeleton.end_sites[2], [0, -40, 0])


def test_loads_matches_load_and_names_the_string(tmp_path):
    a, b = bvh.loads(VALID, name="x.bvh"), bvh.load(write(tmp_path, VALID))
    np.testing.assert_array_equal(a.rotations, b.rotations)
    with pytest.raises(BVHError, match=r"^<string>:"):
        bvh.loads(VALID.replace("Frames: 2", "Frames: two"))


def test_crlf_tabs_bom_latin1_and_root_with_three_channels(tmp_path):
    m = bvh.load(write(tmp_path, VALID.replace("\n", "\r\n").replace("  ", "\t")))
    assert m.num_frames == 2
    p = tmp_path / "bom.bvh"
    p.write_bytes(b"\xef\xbb\xbf" + VALID.encode())
    assert bvh.load(p).skeleton.names[0] == "mixamorig:Hips"
    p = tmp_path / "latin1.bvh"
    p.write_bytes(VALID.replace("Spine", "R\u00fccken").encode("latin-1"))
    assert bvh.load(p).skeleton.names[1] == "R\u00fccken"
    text = VALID.replace("CHANNELS 6 Xposition Yposition Zposition Zrotation", "CHANNELS 3 Zrotation")
    text = "\n".join(" ".join(s.split()[3:]) if s[:1].isdigit() else s for s in text.split("\n"))
    m = bvh.loads(text)
    np.testing.assert_allclose(m.translations[:, 0], [[0, 90, 0]] * 2)
    assert m.skeleton.channels[0] == ("Zrotation", "Xrotation", "Yrotation")


def test_non_integer_rate_is_kept_as_a_float():
    m = bvh.loads(VALID.replace("3.33333e-02", "0.0333667"))
    assert abs(m.fps - 1 / 0.0333667) < 1e-9
    assert bvh.loads(VALID.replace("3.33333e-02", "8.33e-03")).fps == 1 / 8.33e-03  # 120.05: 0.04% off
    assert bvh.loads(VALID.replace("3.33333e-02", "0.0083333")).fps == 120.0


# ----------------------------------------------------------------------------------------------------
# Malformed files: BVHError naming the file, the right line and the reason


def at(needle, nth=0):
    """Expected error line: the nth line containing ``needle``."""
    return lambda text: [i for i, s in enumerate(text.split("\n"), 1) if needle in s][nth]


def last_line(text):
    return max(i for i, s in enumerate(text.split("\n"), 1) if s.strip())


ROWS = "1 90 2 10 20 30 5 -6 7 1 2 3 5 -10 0\n1.5 91 2 11 21 31 5 -6 8 1 2 3 5 -10 0.5\n"
HEAD = VALID.split("MOTION")[0]
MALFORMED = [
    ("missing close brace", lambda t: t.replace("    }\n  }\n  JOINT Leg", "    }\n  JOINT Leg"), at("MOTION"),
     "unbalanced"),
    ("extra close brace", lambda t: t.replace("}\nMOTION", "}\n}\nMOTION"), lambda t: at("MOTION")(t) - 1,
     "unbalanced"),
    ("unknown channel", lambda t: t.replace("Yrotation Xrotation\n", "Yrotation Wrotation\n"), at("Wrotation"),
     "unknown channel 'Wrotation'"),
    ("channel count not 3 or 6", lambda t: t.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"),
     at("CHANNELS 4"), "only 3 or 6"),
    ("count differs from names", lambda t: t.replace("CHANNELS 3 Zrotation Yrotation Xrotation",
                                                     "CHANNELS 6 Zrotation Yrotation Xrotation"),
     at("CHANNELS 6 Zrotation"), "says 6 but lists 3"),
    ("repeated rotation axis", lambda t: t.replace("Zrotation Yrotation Xrotation", "Zrotation Yrotation Yrotation"),
     at("Yrotation Yrotation"), "one X, Y and Z rotation"),
    ("row too short", lambda t: t.replace("-10 0\n1.5", "-10\n1.5"), at("1 90 2"), "has 14 values, expected 15"),
    ("wrapped row", lambda t: t.replace("5 -6 8 1 2 3", "5 -6 8\n1 2 3"), at("1.5 91"), "has 9 values"),
    ("frames more than rows", lambda t: t.replace("Frames: 2", "Frames: 3"), at("Frames:"),
     "'Frames: 3' but the file has 2 motion rows"),
    ("frames fewer than rows", lambda t: t.replace("Frames: 2", "Frames: 1"), at("Frames:"), "has 2 motion rows"),
    ("zero frames", lambda t: HEAD + "MOTION\nFrames: 0\nFrame Time: 0.03\n", at("Frames:"), "0 frames"),
    ("nan", lambda t: t.replace("1.5 91", "1.5 nan"), at("1.5 nan"), "NaN or inf"),
    ("inf", lambda t: t.replace("1.5 91", "1.5 -inf"), at("-inf"), "NaN or inf"),
    ("nan offset", lambda t: t.replace("OFFSET 5 -10 0", "OFFSET 5 nan 0"), at("5 nan"), "non-finite"),
    ("frame time zero", lambda t: t.replace("3.33333e-02", "0.0"), at("Frame Time"), "positive"),
    ("frame time negative", lambda t: t.replace("3.33333e-02", "-3e-2"), at("Frame Time"), "positive"),
    ("frame time inf", lambda t: t.replace("3.33333e-02", "inf"), at("Frame Time"), "non-finite"),
    ("unparsable frame time", lambda t: t.replace("3.33333e-02", "0,033"), at("Frame Time"), "'0,033'"),
    ("unparsable frames", lambda t: t.replace("Frames: 2", "Frames: 2.5"), at("Frames:"), "'2.5'"),
    ("unparsable motion value", lambda t: t.replace("1.5 91", "1.5 9x1"), at("9x1"), "'9x1'"),
    ("underscore number", lambda t: t.replace("1.5 91", "1.5 9_1"), at("9_1"), "'9_1'"),
    ("unparsable offset", lambda t: t.replace("OFFSET 0 90 0", "OFFSET 0 abc 0"), at("abc"), "'abc'"),
    ("offset too short", lambda t: t.replace("OFFSET 0 10 0", "OFFSET 0 10"), at("OFFSET 0 10"), "3 numbers"),
    ("missing motion section", lambda t: HEAD, last_line, "end of file, expected MOTION"),
    ("missing frame rows header", lambda t: HEAD + "MOTION\n", last_line, "Frames:"),
    ("missing hierarchy", lambda t: t.replace("HIERARCHY\n", ""), at("ROOT"), "expected HIERARCHY"),
    ("missing root", lambda t: t.replace("ROOT mixamorig:Hips\n", ""), at("{"), "ROOT"),
    ("joint without channels", lambda t: t.replace("    CHANNELS 3 Zrotation Yrotation Xrotation\n", ""),
     at("End Site"), "'Spine' has no CHANNELS"),
    ("duplicate joint name", lambda t: t.replace("JOINT Leg", "JOINT Spine"), at("JOINT Spine", 1),
     "duplicate joint name 'Spine'"),
    ("garbage in joint", lambda t: t.replace("  JOINT Leg", "  JIONT Leg"), at("JIONT"), "unexpected 'JIONT'"),
]


@pytest.mark.parametrize("case,mutate,line,reason", MALFORMED, ids=[c[0] for c in MALFORMED])
def test_malformed_raises_bvherror_with_file_line_and_reason(tmp_path, case, mutate, line, reason):
    text = mutate(VALID)
    assert text != VALID
    p = write(tmp_path, text, name="bad.bvh")
    with pytest.raises(BVHError) as info:
        bvh.load(p)
    msg = str(info.value)
    assert isinstance(info.value, DataError)
    assert msg.startswith(f"{p}:{line(text)}: "), msg
    assert reason in msg, msg
    assert "\n" not in msg


def test_first_bad_motion_row_is_reported(tmp_path):
    rows = [" ".join(["0"] * 15)] * 50
    rows[30], rows[40] = rows[30][:-2], rows[40].replace("0", "x", 1)  # short row 30, bad number in 40
    text = HEAD + "MOTION\nFrames: 50\nFrame Time: 0.01\n" + "\n".join(rows) + "\n"
    with pytest.raises(BVHError, match=rf":{at('MOTION')(text) + 3 + 30}: motion row has 14 values"):
        bvh.loads(text)
    rows[30] = rows[29]
    text = HEAD + "MOTION\nFrames: 50\nFrame Time: 0.01\n" + "\n".join(rows) + "\n"
    with pytest.raises(BVHError, match=rf":{at('MOTION')(text) + 3 + 40}: cannot parse motion value 'x'"):
        bvh.loads(text)


def test_absurdly_deep_hierarchy_is_a_bvherror_not_a_crash():
    depth = 5000
    text = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
    text += "".join(f"JOINT j{k}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n" for k in range(depth))
    text += "}\n" * (depth + 1) + "MOTION\nFrames: 1\nFrame Time: 0.1\n" + " ".join(["0"] * 3 * (depth + 1))
    with pytest.raises(BVHError, match="nested too deeply"):
        bvh.loads(text, name="deep.bvh")


def test_unreadable_files_name_the_file(tmp_path):
    for text in ["", "\n\n", " \r\n\t\n"]:
        with pytest.raises(BVHError, match=re.escape(f"{tmp_path / 'e.bvh'}: empty file")):
            bvh.load(write(tmp_path, text, "e.bvh"))
    with pytest.raises(BVHError, match=re.escape(f"{tmp_path / 'nope.bvh'}: no such file")):
        bvh.load(tmp_path / "nope.bvh")
    with pytest.raises(BVHError, match="is a directory"):
        bvh.load(tmp_path)
    (tmp_path / "bin.bvh").write_bytes(b"\x00\xff\x00HIER")
    with pytest.raises(BVHError, match=re.escape(f"{tmp_path / 'bin.bvh'}: binary data")):
        bvh.load(tmp_path / "bin.bvh")


# ----------------------------------------------------------------------------------------------------
# Writer


def test_save_errors_are_clear_and_leave_nothing_behind(tmp_path):
    m = bvh.load(write(tmp_path, VALID))
    with pytest.raises(BVHError, match="output directory .* does not exist"):
        bvh.save(m, tmp_path / "missing" / "out.bvh")
    assert not (tmp_path / "missing").exists()
    with pytest.raises(BVHError, match="is a directory"):
        bvh.save(m, tmp_path)
    out = tmp_path / "out.bvh"
    bvh.save(m, out)
    before = out.read_bytes()
    bad = m.replace(translations=np.where(np.arange(3)[None, :, None] == 1, np.nan, m.translations))
    with pytest.raises(BVHError, match="NaN or inf"):
        bvh.save(bad, out)
    assert out.read_bytes() == before  # untouched
    assert sorted(os.listdir(tmp_path)) == ["clip.bvh", "out.bvh"]  # no temporary files left
    unordered = Motion(Skeleton(("a", "b", "c"), np.array([-1, 2, 0]), np.zeros((3, 3))), m.rotations,
                       m.translations, 30.0)
    with pytest.raises(BVHError, match="parent before its children"):
        bvh.dumps(unordered)


def test_motion_built_in_code_with_default_channels_saves(tmp_path):
    rng = np.random.default_rng(0)
    sk = Skeleton(("root", "a", "b", "c"), np.array([-1, 0, 1, 0]), rng.normal(size=(4, 3)) * 10)
    rot = R.quat_normalize(rng.normal(size=(7, 4, 4)))
    trans = np.broadcast_to(sk.offsets, (7, 4, 3)).copy()
    trans[:, 0] += rng.normal(size=(7, 3))
    m = Motion(sk, rot, trans, fps=60)
    p = tmp_path / "code.bvh"
    bvh.save(m, p)
    m2 = bvh.load(p)
    assert m2.skeleton.channels == sk.channels and m2.fps == 60.0 and m2.skeleton.end_sites == {}
    assert quat_close(m2.rotations, m.rotations, 1e-5)
    np.testing.assert_allclose(numpy_fk(m2), numpy_fk(m), atol=1e-3)
    assert "Frame Time: 0.016666666666666666" in p.read_text()
    bvh.save(m.replace(rotations=2.5 * m.rotations), p)  # quaternions are normalised on writing
    assert quat_close(bvh.load(p).rotations, m.rotations, 1e-5)
    with pytest.raises(BVHError, match="zero-length quaternions"):
        bvh.save(m.replace(rotations=0 * m.rotations), p)


# ----------------------------------------------------------------------------------------------------
# Independent reference: a plain parser + FK with scipy rotations (shares no code with jaxgest).


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


def test_small_file_fk_matches_reference(tmp_path):
    p = write(tmp_path, VALID)
    ref, names, parents = reference_fk(p)
    m = bvh.load(p)
    assert tuple(names) == m.skeleton.names and parents == list(m.skeleton.parents)
    np.testing.assert_allclose(numpy_fk(m), ref, atol=1e-9)


ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
NAME_CHARS = st.characters(min_codepoint=33, max_codepoint=0x24F, blacklist_characters="{}",
                           blacklist_categories=("Cc", "Cs", "Zs", "Zl", "Zp"))


@st.composite
def random_motion(draw):
    """Random tree of 1-8 joints in depth-first order, per-joint Euler orders, 3/6 channels with the
    position channels anywhere, End Sites, names with colons and any non-space characters."""
    J = draw(st.integers(1, 8))
    parents = [-1]
    for j in range(1, J):  # depth-first file order: the parent lies on the path from the root to j - 1
        path, a = [], j - 1
        while a >= 0:
            path.append(a)
            a = parents[a]
        parents.append(draw(st.sampled_from(path)))
    names = draw(st.lists(st.text(NAME_CHARS, min_size=1, max_size=8), min_size=J, max_size=J, unique=True))
    names[0] = "mixamorig:" + names[0]
    assume(len(set(names)) == J)
    chans, six = [], []
    for j in range(J):
        rot = [f"{a}rotation" for a in draw(st.sampled_from(ORDERS))]
        if draw(st.booleans()):
            pos = [f"{a}position" for a in draw(st.permutations("XYZ"))]
            slots = sorted(draw(st.lists(st.integers(0, 5), min_size=3, max_size=3, unique=True)))
            merged = [None] * 6
            for s, c in zip(slots, pos):
                merged[s] = c
            it = iter(rot)
            rot = [c if c else next(it) for c in merged]
        chans.append(tuple(rot))
        six.append(len(rot) == 6)
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    F = draw(st.integers(1, 5))
    offsets = rng.normal(scale=10, size=(J, 3))
    ends = {j: rng.normal(scale=5, size=3) for j in range(J) if j not in parents or draw(st.booleans())}
    sk = Skeleton(names=tuple(names), parents=np.array(parents), offsets=offsets, channels=tuple(chans),
                  end_sites=ends)
    angles = rng.uniform(-179, 179, size=(F, J, 3))
    angles[..., 1] = rng.uniform(-89, 89, size=(F, J))
    orders = ["".join(c[0] for c in ch if c.endswith("rotation")) for ch in chans]
    rots = np.stack([R.euler_to_quat(angles[:, j], orders[j]) for j in range(J)], axis=1)
    trans = np.broadcast_to(offsets, (F, J, 3)).copy()
    trans[:, np.array(six)] += rng.normal(scale=50, size=(F, int(np.sum(six)), 3))
    fps = draw(st.sampled_from([24.0, 29.97, 30.0, 60.0, 120.0, 1000 / 7]))
    return Motion(sk, rots, trans, fps=fps)


@settings(max_examples=25, deadline=None)
@given(random_motion())
def test_save_load_round_trip_on_generated_skeletons(tmp_path_factory, m):
    p = tmp_path_factory.mktemp("rt") / "m.bvh"
    bvh.save(m, p)
    m2 = bvh.load(p)
    sk, sk2 = m.skeleton, m2.skeleton
    assert sk2.names == sk.names and sk2.channels == sk.channels
    np.testing.assert_array_equal(sk2.parents, sk.parents)
    np.testing.assert_allclose(sk2.offsets, sk.offsets, atol=1e-6)
    assert sorted(sk2.end_sites) == sorted(sk.end_sites)
    for j in sk.end_sites:
        np.testing.assert_allclose(sk2.end_sites[j], sk.end_sites[j], atol=1e-6)
    assert m2.fps == pytest.approx(m.fps, rel=1e-12)
    assert quat_close(m.rotations, m2.rotations, 1e-5)
    np.testing.assert_allclose(numpy_fk(m2), numpy_fk(m), atol=1e-3)
    ref, names, parents = reference_fk(p)  # the saved file reads right in the independent parser
    assert tuple(names) == sk.names and parents == list(sk.parents)
    np.testing.assert_allclose(ref, numpy_fk(m), atol=1e-3)
    def body(text):
        return [s for s in text.split("\n") if not s.startswith("Frame Time")]

    assert body(bvh.dumps(m2)) == body(p.read_text(encoding="utf-8"))  # stable once values are on the grid


# ----------------------------------------------------------------------------------------------------
# Real data (skipped cleanly when ../shared is absent)


def header_frames(path):
    with open(path) as f:
        return int(next(s for s in f if s.startswith("Frames:")).split()[1])


@pytest.mark.realdata
def test_every_bandai_file_loads_and_matches_reference_fk(bandai_dir, tmp_path):
    files = sorted(bandai_dir.glob("*.bvh"))
    assert len(files) == 174
    for k, f in enumerate(files):
        m = bvh.load(f)
        assert m.skeleton.num_joints == 22 and m.fps == 30.0 and m.skeleton.names[:2] == ("joint_Root", "Hips")
        assert all(len(c) == 6 for c in m.skeleton.channels)
        assert m.num_frames == header_frames(f)
        if k % 3:  # the independent parser + scipy FK on every third file keeps this test at a few seconds
            continue
        ref, names, parents = reference_fk(f)
        assert tuple(names) == m.skeleton.names and parents == list(m.skeleton.parents)
        np.testing.assert_allclose(numpy_fk(m), ref, atol=1e-2)
        if k % 45 == 0:  # save/reload round trip on a few files
            out = tmp_path / f.name
            bvh.save(m, out)
            m2 = bvh.load(out)
            assert m2.skeleton.names == m.skeleton.names and m2.skeleton.channels == m.skeleton.channels
            assert quat_close(m.rotations, m2.rotations, 1e-5)
            np.testing.assert_allclose(numpy_fk(m2), ref, atol=1e-3)
            np.testing.assert_allclose(reference_fk(out)[0], ref, atol=1e-3)


@pytest.mark.realdata
def test_zeggs_file_loads_and_matches_reference_fk(zeggs_dir, tmp_path):
    f = zeggs_dir / "067_Speech_2_x_1_0.bvh"
    m = bvh.load(f)
    assert m.skeleton.num_joints == 75 and m.fps == 30.0 and m.num_frames == header_frames(f)
    assert len(m.skeleton.channels[0]) == 6 and all(c == ("Zrotation", "Yrotation", "Xrotation")
                                                     for c in m.skeleton.channels[1:])
    ref, names, parents = reference_fk(f)
    assert tuple(names) == m.skeleton.names and parents == list(m.skeleton.parents)
    np.testing.assert_allclose(numpy_fk(m), ref, atol=1e-2)
    short = m.replace(rotations=m.rotations[:300], translations=m.translations[:300])  # round trip on 10 s
    out = tmp_path / "z.bvh"
    bvh.save(short, out)
    m2 = bvh.load(out)
    assert m2.skeleton.names == m.skeleton.names and m2.skeleton.channels == m.skeleton.channels
    assert quat_close(short.rotations, m2.rotations, 1e-5)
    np.testing.assert_allclose(numpy_fk(m2), ref[:300], atol=1e-3)
    np.testing.assert_allclose(reference_fk(out)[0], ref[:300], atol=1e-3)
    try:
        from jaxgest.motion.kinematics import forward_kinematics
    except ImportError:  # pragma: no cover
        return
    np.testing.assert_allclose(forward_kinematics(m), ref, atol=1e-2)

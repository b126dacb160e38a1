"""Strict BVH reader/writer: valid files in every notation, malformed inputs with file:line and reason, save errors.

Round trips, the independent reference FK and the real files are in test_bvh_reference.py.
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest

from jaxgest.runtime.errors import DataError
from jaxgest.motion import bvh
from jaxgest.motion import rotations as R
from jaxgest.motion.bvh import BVHError
from jaxgest.motion.skeleton import Motion, Skeleton
from bvh_testing import VALID, numpy_fk, quat_close, write

Rotation = pytest.importorskip("scipy.spatial.transform").Rotation


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

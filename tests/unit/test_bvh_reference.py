"""BVH files against an independent reference: the parser + FK of bvh_testing.reference_fk (NumPy and scipy, no
jaxgest code) on a small file, on random skeletons after a save/load round trip, and on every real file.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from jaxgest.motion import bvh
from jaxgest.motion import rotations as R
from jaxgest.motion.kinematics import forward_kinematics
from jaxgest.motion.skeleton import Motion, Skeleton
from bvh_testing import VALID, numpy_fk, quat_close, reference_fk, write


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
        ref, names, parents = reference_fk(f)  # every file: the independent parser + scipy FK (~5 s in all)
        assert tuple(names) == m.skeleton.names and parents == list(m.skeleton.parents)
        np.testing.assert_allclose(numpy_fk(m), ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(forward_kinematics(m), ref, rtol=0, atol=1e-9)
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
    np.testing.assert_allclose(numpy_fk(m), ref, rtol=0, atol=1e-9)
    short = m.replace(rotations=m.rotations[:300], translations=m.translations[:300])  # round trip on 10 s
    out = tmp_path / "z.bvh"
    bvh.save(short, out)
    m2 = bvh.load(out)
    assert m2.skeleton.names == m.skeleton.names and m2.skeleton.channels == m.skeleton.channels
    assert quat_close(short.rotations, m2.rotations, 1e-5)
    np.testing.assert_allclose(numpy_fk(m2), ref[:300], atol=1e-3)
    np.testing.assert_allclose(reference_fk(out)[0], ref[:300], atol=1e-3)
    np.testing.assert_allclose(forward_kinematics(m), ref, rtol=0, atol=1e-9)

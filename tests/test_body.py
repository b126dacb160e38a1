"""The 21-joint body: exp-map representation, joint maps, retargeting by direction matching."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.errors import DataError
from jaxgest.motion import bvh
from jaxgest.motion import body as B
from jaxgest.motion import kinematics as K
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton


def test_body_layout():
    sk = B.body_skeleton()
    assert sk.num_joints == 21 and len(B.UPPER) == 13 and len(B.LOWER) == 8
    assert B.UPPER_CHANNELS == 39 and B.LOWER_CHANNELS == 24
    assert set(B.BODY) == set(sk.names)
    assert B.detect_map(sk) == "bandai_namco"


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_body_round_trip_is_lossless_on_random_body_motions(seed):
    rng = np.random.default_rng(seed)
    sk = B.body_skeleton()
    F = 5
    rot = R.quat_normalize(rng.normal(size=(F, 21, 4)))
    trans = np.broadcast_to(sk.offsets, (F, 21, 3)).copy()
    trans[:, 0] += rng.normal(scale=20, size=(F, 3))
    m = Motion(sk, rot, trans, fps=60)
    c = B.motion_to_body(m)
    assert c.upper.shape == (F, 39) and c.lower.shape == (F, 24)
    back = B.body_to_motion(c.upper, c.lower, m, yaw=c.yaw, floor=False)
    assert R.quat_angle(R.quat_mul(R.quat_inv(back.rotations), m.rotations)).max() < 1e-6
    np.testing.assert_allclose(K.forward_kinematics(back), K.forward_kinematics(m), atol=1e-4)
    # The hips exp-map carries no yaw: its rotation has no twist about the vertical axis.
    hips_q = R.expmap_to_quat(c.upper[:, :3])
    _, twist = K.swing_twist(R.quat_inv(hips_q), np.array([0.0, 1.0, 0.0]))
    assert R.quat_angle(twist).max() < 1e-6


def test_floor_contact_on_output():
    sk = B.body_skeleton()
    rng = np.random.default_rng(3)
    m = Motion(sk, R.quat_normalize(rng.normal(size=(4, 21, 4))), np.broadcast_to(sk.offsets, (4, 21, 3)), 60)
    c = B.motion_to_body(m)
    out = B.body_to_motion(c.upper, c.lower, m)
    feet = [sk.index(n) for n in B.FEET]
    np.testing.assert_allclose(K.forward_kinematics(out)[:, feet, 1].min(axis=1), 0, atol=1e-9)


def test_unknown_skeleton_is_a_clear_error():
    sk = Skeleton(names=("root", "a"), parents=np.array([-1, 0]), offsets=np.zeros((2, 3)))
    with pytest.raises(DataError, match="matches no joint map"):
        B.detect_map(sk)
    with pytest.raises(DataError, match="no joint map named"):
        B.load_map("nope")


@pytest.mark.realdata
def test_bandai_round_trip_lossless(bandai_dir):
    for f in sorted(bandai_dir.glob("*.bvh"))[:3]:
        m = bvh.load(f)
        assert B.detect_map(m.skeleton) == "bandai_namco"
        c = B.motion_to_body(m)
        back = B.body_to_motion(c.upper, c.lower, m, yaw=c.yaw, floor=False)
        assert R.quat_angle(R.quat_mul(R.quat_inv(back.rotations), m.rotations)).max() < 1e-6
        np.testing.assert_allclose(K.forward_kinematics(back), K.forward_kinematics(m), atol=1e-4)


@pytest.mark.realdata
def test_zeggs_retargeting_keeps_bone_directions(zeggs_dir):
    z = bvh.load(zeggs_dir / "067_Speech_2_x_1_0.bvh")
    assert B.detect_map(z.skeleton) == "zeggs"
    jm = B.load_map("zeggs")["joints"]
    zb = B.retarget_to_body(z)
    pz, pb = K.forward_kinematics(z), K.forward_kinematics(zb)
    sb = zb.skeleton
    cosines = []
    for b, s in jm.items():
        for k in np.flatnonzero(sb.parents == sb.index(b)):
            v1 = pb[:, k] - pb[:, sb.index(b)]
            v2 = pz[:, z.skeleton.index(jm[sb.names[k]])] - pz[:, z.skeleton.index(s)]
            cosines.append(np.mean(np.sum(v1 * v2, -1) / np.linalg.norm(v1, axis=-1) / np.linalg.norm(v2, axis=-1)))
    assert np.mean(cosines) > 0.98 and min(cosines) > 0.9
    # ... and back onto the ZEGGS rig: mapped joints return to their places.
    c = B.motion_to_body(z)
    back = B.body_to_motion(c.upper, c.lower, z, yaw=c.yaw, floor=False)
    idx = [z.skeleton.index(s) for s in jm.values()]
    np.testing.assert_allclose(K.forward_kinematics(back)[:, idx], pz[:, idx], atol=0.5)
    assert back.skeleton is z.skeleton and back.num_frames == z.num_frames

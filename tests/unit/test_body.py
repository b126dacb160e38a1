"""The 21-joint body: exp-map representation, joint maps, retargeting by direction matching."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.runtime.errors import DataError
from jaxgest.motion import bvh
from jaxgest.motion import body as B
from jaxgest.motion import kinematics as K
from jaxgest.motion import root_motion as RM
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
    # Any template of the rig will do when yaw and root position are given (here: the T-pose at the origin).
    at_origin = np.broadcast_to(sk.offsets, (F, 21, 3)).copy()
    at_origin[:, 0] = 0.0
    tpose = Motion(sk, np.tile(B.body_tpose(), (F, 1, 1)), at_origin, 60)
    other = B.body_to_motion(c.upper, c.lower, tpose, yaw=c.yaw, root_position=c.root_position, floor=False)
    np.testing.assert_allclose(K.forward_kinematics(other), K.forward_kinematics(m), atol=1e-4)
    # The hips exp-map carries no yaw: its rotation has no twist about the vertical axis.
    hips_q = R.expmap_to_quat(c.upper[:, :3])
    _, twist = RM.swing_twist(R.quat_inv(hips_q), np.array([0.0, 1.0, 0.0]))
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
    # A clip through the body onto another clip's rig instance, with its yaw and root path.
    a, b = (bvh.load(f) for f in sorted(bandai_dir.glob("*.bvh"))[3:5])
    F = min(a.num_frames, b.num_frames)
    a, b = (x.replace(rotations=x.rotations[:F], translations=x.translations[:F]) for x in (a, b))
    c = B.motion_to_body(a)
    out = B.body_to_motion(c.upper, c.lower, b, yaw=c.yaw, root_position=c.root_position, floor=False)
    np.testing.assert_allclose(K.forward_kinematics(out), K.forward_kinematics(a), atol=1e-4)
    with pytest.raises(ValueError, match="expected"):
        B.body_to_motion(c.upper[1:], c.lower, b)


def test_body_tpose_is_a_standing_t_pose_facing_plus_z():
    sk = B.body_skeleton()
    q = B.body_tpose()
    p = K.forward_kinematics(Motion(sk, q[None], sk.offsets[None], 60))[0]
    at = {n: p[sk.index(n)] for n in sk.names}
    for side, sign in (("L", 1), ("R", -1)):  # character's left = +X
        arm = at[f"Hand_{side}"] - at[f"UpperArm_{side}"]
        np.testing.assert_allclose(arm / np.linalg.norm(arm), [sign, 0, 0], atol=1e-5)
        leg = at[f"Foot_{side}"] - at[f"UpperLeg_{side}"]
        np.testing.assert_allclose(leg / np.linalg.norm(leg), [0, -1, 0], atol=1e-3)
        toe = at[f"Toes_{side}"] - at[f"Foot_{side}"]
        np.testing.assert_allclose(toe / np.linalg.norm(toe), [0, 0, 1], atol=1e-3)
    assert at["Head"][1] > at["Neck"][1] > at["Chest"][1] > at["Hips"][1]
    # The yaw of the T-pose is zero: facing +Z is the canonical heading.
    _, yaw = RM.remove_root_yaw(Motion(sk, q[None], sk.offsets[None], 60))
    assert R.quat_angle(yaw).max() < 1e-9


def _bone_cosines(pa, ska, pb, skb, pairs):
    """Mean cosine per mapped bone (parent->child joints of rig a, matched by ``pairs`` a-name -> b-name)."""
    out = {}
    for a, b in pairs.items():
        j = ska.index(a)
        for k in np.flatnonzero(ska.parents == j):
            if ska.names[k] not in pairs:
                continue
            v1 = pa[:, k] - pa[:, j]
            v2 = pb[:, skb.index(pairs[ska.names[k]])] - pb[:, skb.index(b)]
            c = np.sum(v1 * v2, -1) / np.linalg.norm(v1, axis=-1) / np.linalg.norm(v2, axis=-1)
            out[(a, ska.names[k])] = float(np.mean(c))
    return out


LIMBS = [("UpperArm_L", "LowerArm_L"), ("LowerArm_L", "Hand_L"), ("UpperArm_R", "LowerArm_R"),
         ("LowerArm_R", "Hand_R"), ("UpperLeg_L", "LowerLeg_L"), ("LowerLeg_L", "Foot_L"),
         ("UpperLeg_R", "LowerLeg_R"), ("LowerLeg_R", "Foot_R"), ("Neck", "Head")]


@pytest.fixture(scope="module")
def zeggs_clip(zeggs_dir):
    z = bvh.load(zeggs_dir / "067_Speech_2_x_1_0.bvh")
    return z.replace(rotations=z.rotations[:600], translations=z.translations[:600])


@pytest.mark.realdata
def test_zeggs_to_body_keeps_bone_directions_and_leaf_orientations(zeggs_clip):
    z = zeggs_clip
    assert B.detect_map(z.skeleton) == "zeggs"
    jm = B.load_map("zeggs")["joints"]
    zb = B.retarget_to_body(z)
    cos = _bone_cosines(K.forward_kinematics(zb), zb.skeleton, K.forward_kinematics(z), z.skeleton, jm)
    assert len(cos) == 20 and np.mean(list(cos.values())) > 0.98
    # Limbs and neck follow exactly; the rest differ by the rigs' T-pose proportions only (hips->thigh
    # 0.947, chest->shoulder 0.991, spine 0.999, ZEGGS left wrist 0.9996: constant offsets, not pose errors).
    assert min(cos[b] for b in LIMBS) > 0.999 and cos[("Spine", "Chest")] > 0.998 and min(cos.values()) > 0.94
    # Hands, head, toes turn by the same world rotation away from their T-poses on both rigs.
    gz, gb = K.global_rotations(z), K.global_rotations(zb)
    tz, tb = B.tpose_globals("zeggs", z.skeleton), B.tpose_globals("bandai_namco")
    for b in ("Hand_L", "Hand_R", "Head", "Toes_L", "Hips", "LowerArm_R"):
        s, j = z.skeleton.index(jm[b]), zb.skeleton.index(b)
        dz = R.quat_mul(gz[:, s], R.quat_inv(tz[s]))
        db = R.quat_mul(gb[:, j], R.quat_inv(tb[j]))
        assert R.quat_angle(R.quat_mul(R.quat_inv(dz), db)).max() < 1e-6


@pytest.mark.realdata
def test_zeggs_body_round_trip_is_lossless(zeggs_clip):
    z = zeggs_clip
    c = B.motion_to_body(z)
    assert c.upper.shape == (z.num_frames, 39) and c.lower.shape == (z.num_frames, 24)
    back = B.body_to_motion(c.upper, c.lower, z, yaw=c.yaw, floor=False)
    assert back.skeleton is z.skeleton and back.num_frames == z.num_frames
    assert R.quat_angle(R.quat_mul(R.quat_inv(back.rotations), z.rotations)).max() < 1e-6
    np.testing.assert_allclose(K.forward_kinematics(back), K.forward_kinematics(z), atol=1e-4)


@pytest.mark.realdata
def test_body_onto_zeggs_follows_the_body_and_keeps_unmapped_joints(zeggs_clip, bandai_dir):
    """A Bandai-Namco clip through the body onto the ZEGGS rig: mapped bones point like the body's."""
    bn = bvh.load(bandai_dir / "dataset-1_bow_active_001.bvh")
    F = min(bn.num_frames, zeggs_clip.num_frames, 200)
    bn = bn.replace(rotations=bn.rotations[:F], translations=bn.translations[:F])
    z = zeggs_clip.replace(rotations=zeggs_clip.rotations[:F], translations=zeggs_clip.translations[:F])
    c = B.motion_to_body(bn)
    out = B.body_to_motion(c.upper, c.lower, z, yaw=c.yaw, floor=True)
    # The body clip itself on the canonical body skeleton (hips position from the ZEGGS template).
    bsk = B.body_skeleton()
    ref = B.body_to_motion(c.upper, c.lower, Motion(bsk, np.tile(B.body_tpose(), (F, 1, 1)),
                                                    np.broadcast_to(bsk.offsets, (F, 21, 3)), bn.fps),
                           yaw=c.yaw, floor=False)
    jm = B.load_map("zeggs")["joints"]
    cos = _bone_cosines(K.forward_kinematics(ref), bsk, K.forward_kinematics(out), z.skeleton, jm)
    assert np.mean(list(cos.values())) > 0.98 and min(cos[b] for b in LIMBS) > 0.999
    # Unmapped ZEGGS joints (fingers, Spine, Spine2, Neck1) keep the template's local rotations.
    mapped = {z.skeleton.index(s) for s in jm.values()}
    unmapped = [j for j in range(z.skeleton.num_joints) if j not in mapped]
    assert len(unmapped) == 75 - 21
    np.testing.assert_allclose(out.rotations[:, unmapped], z.rotations[:, unmapped], atol=1e-12)
    feet = RM.foot_joints(z.skeleton)  # feet, toes and toe tips (LeftToeBaseEnd)
    assert len(feet) == 6
    np.testing.assert_allclose(K.forward_kinematics(out)[:, feet, 1].min(axis=1), 0, atol=1e-9)


@pytest.mark.realdata
def test_detect_map_on_real_skeletons(bandai_dir, zeggs_clip):
    assert B.detect_map(bvh.load(bandai_dir / "dataset-1_bow_active_001.bvh").skeleton) == "bandai_namco"
    assert B.detect_map(zeggs_clip.skeleton) == "zeggs"


def test_load_map_returns_a_private_copy():
    a = B.load_map("zeggs")
    a["joints"]["Hips"] = "changed"
    assert B.load_map("zeggs")["joints"]["Hips"] != "changed"
    sk = B.body_skeleton()
    assert B.joint_indices(sk, B.HANDS) == [sk.index("Hand_L"), sk.index("Hand_R")]


def test_memoised_rig_data_is_read_only():
    """The shared body skeleton and T-pose cannot be changed by one caller for every other."""
    sk = B.body_skeleton()
    for a in (sk.offsets, sk.parents, B.tpose_globals("bandai_namco")):
        with pytest.raises(ValueError, match="read-only"):
            a[0] = 0
    assert B.body_tpose().flags.writeable  # derived arrays are the caller's own


def test_other_memoised_structures_are_read_only():
    """The synthetic rig and the FK level plan are memoised too: no caller can change them for another."""
    from jaxgest.motion import kinematics
    from jaxgest.motion import synthetic

    rig = synthetic._rig()
    for a in (rig.ref, rig.axis):
        with pytest.raises(ValueError, match="read-only"):
            a[0] = 0
    with pytest.raises(TypeError):
        rig.lengths["upper_L"] = 0.0
    levels, where = kinematics._fk_levels(tuple(int(p) for p in B.body_skeleton().parents))
    for a in (where, levels[1][0], levels[1][1]):
        with pytest.raises(ValueError, match="read-only"):
            a[0] = 0


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_nearest_branch_keeps_every_rotation_and_the_identity_joints(seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(6, 8, 3))
    v *= rng.uniform(0.0, np.pi, size=(6, 8, 1)) / np.linalg.norm(v, axis=-1, keepdims=True)  # principal |v| <= pi
    ref = B.rest_expmaps(B.LOWER)
    out = B.nearest_branch(v, ref)
    q_in, q_out = R.expmap_to_quat(v), R.expmap_to_quat(out)
    assert R.quat_angle(R.quat_mul(R.quat_inv(q_in), q_out)).max() < 1e-6  # the same rotations
    still = np.linalg.norm(ref, axis=-1) < 1e-9  # joints resting at the identity keep the principal branch
    np.testing.assert_array_equal(out[:, still], v[:, still])
    nearer = np.linalg.norm(out - ref, axis=-1) <= np.linalg.norm(v - ref, axis=-1) + 1e-12
    assert nearer.all()


def test_rest_branch_is_continuous_where_the_principal_exp_map_jumps():
    """An upper leg swinging through the antipode of its rest rotation (pi): the principal exp-map jumps by
    ~2 pi, the branch nearest the rest pose moves by the step of the swing; training data with
    ``expmap_branch="rest"`` has the same rotations and an unchanged upper body."""
    import dataclasses

    from jaxgest.tgst import data as tdata
    from jaxgest.tgst.config import preset

    sk = B.body_skeleton()
    leg = sk.index("UpperLeg_L")
    F = 64
    rot = np.tile(B.body_tpose(), (F, 1, 1))
    axis = B.rest_expmaps(("UpperLeg_L",))[0] / np.pi  # the rest rotation is pi about this axis
    rot[:, leg] = R.expmap_to_quat(np.outer(np.linspace(np.pi - 0.3, np.pi + 0.3, F), axis))  # through pi
    m = Motion(sk, rot, np.broadcast_to(sk.offsets, (F, 21, 3)).copy(), fps=30)
    def branch(name):
        cfg = preset("tiny")
        return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, autoencoder=dataclasses.replace(
            cfg.train.autoencoder, expmap_branch=name)))

    cfg, rest = branch("principal"), branch("rest")
    a, b = tdata.prepare_clips([m], cfg), tdata.prepare_clips([m], rest)
    step = lambda x: np.abs(np.diff(x.reshape(len(x), -1, 3)[:, 0], axis=0)).max()  # UpperLeg_L, per frame
    assert step(a.lower[0]) > 5.0  # the principal branch jumps to the antipode
    assert step(b.lower[0]) < 0.05  # 0.6 rad over the clip
    np.testing.assert_array_equal(a.upper[0], b.upper[0])
    np.testing.assert_array_equal(a.mirrored_upper[0], b.mirrored_upper[0])
    for x, y in ((a.lower[0], b.lower[0]), (a.mirrored_lower[0], b.mirrored_lower[0])):
        qx, qy = (R.expmap_to_quat(z.reshape(len(z), -1, 3).astype(np.float64)) for z in (x, y))
        assert R.quat_angle(R.quat_mul(R.quat_inv(qx), qy)).max() < 1e-3  # float32 storage

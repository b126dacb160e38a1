"""Forward kinematics, mirroring, yaw removal/restoration, floor contact, velocities."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.motion import bvh
from jaxgest.motion import kinematics as K
from jaxgest.motion import root_motion as RM
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton


def chain():
    sk = Skeleton(names=("Hips", "Spine", "Head"), parents=np.array([-1, 0, 1]),
                  offsets=np.array([[0.0, 100, 0], [0, 10, 0], [0, 20, 0]]))
    return sk


def test_fk_hand_computed_chain():
    sk = chain()
    rot = np.zeros((1, 3, 4))
    rot[..., 0] = 1
    rot[0, 1] = R.euler_to_quat(np.array([90.0, 0, 0]), "ZXY")  # spine bends 90 deg about Z
    trans = np.broadcast_to(sk.offsets, (1, 3, 3)).copy()
    trans[0, 0] = [5, 100, 0]
    pos = K.forward_kinematics(Motion(sk, rot, trans, fps=30))
    np.testing.assert_allclose(pos[0], [[5, 100, 0], [5, 110, 0], [-15, 110, 0]], atol=1e-12)


def random_motion(rng, sk, F=6):
    rot = R.quat_normalize(rng.normal(size=(F, sk.num_joints, 4)))
    trans = np.broadcast_to(sk.offsets, (F, sk.num_joints, 3)).copy()
    trans[:, 0] += rng.normal(scale=10, size=(F, 3))
    return Motion(sk, rot, trans, fps=30)


def test_jnp_fk_equals_numpy_fk():
    rng = np.random.default_rng(0)
    m = random_motion(rng, chain())
    f = jax.jit(lambda r, t: K.fk_positions(r, t, tuple(int(p) for p in m.skeleton.parents)))
    out = f(jnp.asarray(m.rotations, jnp.float32), jnp.asarray(m.translations, jnp.float32))
    np.testing.assert_allclose(np.asarray(out), K.forward_kinematics(m), atol=1e-3)



def test_joint_major_expmap_fk_equals_fk_positions():
    """The training layout of FK (joints leading, exp-maps in) gives fk_positions's positions,
    gradients included; a wrong layout is one clear error."""
    rng = np.random.default_rng(1)
    sk = sym_skeleton()
    parents = tuple(int(p) for p in sk.parents)
    ex = jnp.asarray(rng.normal(scale=0.8, size=(3, 5, len(parents), 3)), jnp.float32)  # (B, F, J, 3)
    ex = ex.at[0, 0, 2].set(0.0)  # a zero rotation (the small-angle branch)
    offsets = np.asarray(sk.offsets, np.float32)

    def reference(e):
        return K.fk_positions(R.expmap_to_quat(e), jnp.broadcast_to(jnp.asarray(offsets), e.shape), parents)

    def joint_major(e):
        return jnp.moveaxis(K.fk_expmap_positions_joint_major(jnp.moveaxis(e, -2, 0), offsets, parents), 0, -2)

    np.testing.assert_allclose(joint_major(ex), reference(ex), atol=1e-4)
    w = jnp.asarray(rng.normal(size=ex.shape), jnp.float32)
    g_ref, g_new = (jax.grad(lambda e, f=f: jnp.sum(jnp.sin(f(e)) * w))(ex) for f in (reference, joint_major))
    np.testing.assert_allclose(g_new, g_ref, atol=1e-4)
    with pytest.raises(ValueError, match="expmaps must be"):
        K.fk_expmap_positions_joint_major(ex, offsets, parents)  # joints not leading

def sym_skeleton():
    names = ("Hips", "Spine", "UpperLeg_L", "Foot_L", "UpperLeg_R", "Foot_R", "Arm_L", "Arm_R")
    parents = np.array([-1, 0, 0, 2, 0, 4, 1, 1])
    # Left bones along +X, right bones along -X in their own frames, as in Bandai-Namco.
    offsets = np.array([[0, 90.0, 0], [0, 10, 0], [10, -5, 0], [40, 0, 0], [-10, -5, 0], [-40, 0, 0],
                        [15, 20, 0], [-15, 20, 0]])
    return Skeleton(names=names, parents=parents, offsets=offsets)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_mirror_twice_is_identity_and_positions_reflect(seed):
    m = random_motion(np.random.default_rng(seed), sym_skeleton())
    mm = K.mirror(K.mirror(m))
    assert R.quat_angle(R.quat_mul(R.quat_inv(mm.rotations), m.rotations)).max() < 1e-9
    np.testing.assert_allclose(mm.translations, m.translations, atol=1e-9)
    perm = K.mirror_pairs(m.skeleton)
    reflected = K.forward_kinematics(m)[:, perm] * [-1, 1, 1]
    np.testing.assert_allclose(K.forward_kinematics(K.mirror(m)), reflected,
                               atol=1e-9)
    # On a symmetric rig the mirrored local translations are the rig's own offsets (a valid pose).
    rest = np.broadcast_to(m.skeleton.offsets[1:], (6, 7, 3))
    np.testing.assert_allclose(K.mirror(m).translations[:, 1:], rest,
                               atol=1e-9)


def _random_rotation(rng):
    return R.quat_to_matrix(R.quat_normalize(rng.normal(size=4)))


def turned_rig(rng):
    """A left/right-symmetric rig whose joint frames are arbitrary: random T-pose frames for the central and
    left joints, and right frames that are the reflected left ones times a random local reflection (the
    Bandai-Namco case is ``-I``: its right arm frames are the left ones turned 180 deg about the bone).

    Returns (skeleton, T-pose world rotations (J, 4), T-pose world positions (J, 3)); offsets are the T-pose
    bones in the parents' T-pose frames, so the identity pose is NOT the T-pose.
    """
    names = ("Hips", "Spine", "Neck", "Head", "Shoulder_L", "Arm_L", "Hand_L", "Shoulder_R", "Arm_R", "Hand_R",
             "Leg_L", "Foot_L", "Leg_R", "Foot_R")
    parents = np.array([-1, 0, 1, 2, 1, 4, 5, 1, 7, 8, 0, 10, 0, 12])
    S = np.diag([-1.0, 1.0, 1.0])
    pos = np.array([[0, 90, 0], [0, 130, 0], [0, 150, 0], [0, 160, 0], [5, 145, 0], [18, 145, 0], [45, 145, 0],
                    [-5, 145, 0], [-18, 145, 0], [-45, 145, 0], [10, 85, 0], [10, 45, 0], [-10, 85, 0],
                    [-10, 45, 0]], dtype=np.float64)
    T = np.empty((len(names), 3, 3))
    for j, n in enumerate(names):
        if not n.endswith("_R"):
            T[j] = _random_rotation(rng)
    for j, n in enumerate(names):
        if n.endswith("_R"):
            local = -_random_rotation(rng)  # any reflection of the local frame (det -1)
            T[j] = S @ T[names.index(n[:-2] + "_L")] @ local
    offsets = np.array([T[p].T @ (pos[j] - pos[p]) if p >= 0 else pos[j] for j, p in enumerate(parents)])
    sk = Skeleton(names=names, parents=parents, offsets=offsets)
    return sk, R.matrix_to_quat(T), pos


def pose_from_world(sk, g, root):
    """One-frame Motion with world rotations ``g`` (J, 4) and root position ``root``."""
    local = g.copy()
    for j, p in enumerate(sk.parents):
        if p >= 0:
            local[j] = R.quat_mul(R.quat_inv(g[p]), g[j])
    trans = sk.offsets.copy()
    trans[0] = root
    return Motion(sk, local[None], trans[None], fps=30)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_mirror_with_tpose_keeps_the_representation(seed):
    """With the rig's T-pose, mirroring (a) reflects world positions exactly with L/R swapped and (b) maps a
    symmetric pose onto itself, local rotations included, on a rig with arbitrary joint frames."""
    rng = np.random.default_rng(seed)
    sk, tpose, tpos = turned_rig(rng)
    perm = K.mirror_pairs(sk)
    # (a) any motion: positions reflected to rounding, twice = identity
    m = random_motion(rng, sk)
    mm = K.mirror(m, tpose=tpose)
    reflected = K.forward_kinematics(m)[:, perm] * [-1, 1, 1]
    np.testing.assert_allclose(K.forward_kinematics(mm), reflected, atol=1e-9)
    back = K.mirror(mm, tpose=tpose)
    assert R.quat_angle(R.quat_mul(R.quat_inv(back.rotations), m.rotations)).max() < 1e-9
    np.testing.assert_allclose(back.translations, m.translations, atol=1e-9)
    # (b) the T-pose and a random symmetric pose (each side turned by mirror-image world rotations, central
    # joints about the left-right axis) are their own mirror images
    S = np.diag([-1.0, 1.0, 1.0])
    d = np.empty((sk.num_joints, 3, 3))
    for j in range(sk.num_joints):
        if perm[j] == j:
            d[j] = R.quat_to_matrix(R.expmap_to_quat(np.array([rng.normal(), 0.0, 0.0])))
        elif perm[j] > j:
            d[j] = _random_rotation(rng)
            d[perm[j]] = S @ d[j] @ S
    tm = R.quat_to_matrix(tpose)
    for g in (tpose, R.matrix_to_quat(d @ tm)):
        sym = pose_from_world(sk, g, np.array([0.0, 90.0, 3.0]))
        np.testing.assert_allclose(K.forward_kinematics(sym)[:, perm] * [-1, 1, 1], K.forward_kinematics(sym),
                                   atol=1e-9)  # the pose is symmetric
        assert R.quat_angle(R.quat_mul(R.quat_inv(K.mirror(sym, tpose=tpose).rotations), sym.rotations)).max() < 1e-9
        # without the T-pose, positions stay right but the local rotations leave the representation
        np.testing.assert_allclose(K.forward_kinematics(K.mirror(sym, keep_rig_offsets=False)),
                                   K.forward_kinematics(sym), atol=1e-9)
    assert R.quat_angle(R.quat_mul(R.quat_inv(K.mirror(sym).rotations), sym.rotations)).max() > 0.1


def test_mirror_frames_without_tpose_inherit_the_parent_on_ties():
    """A joint whose only child lies on an axis (Bandai-Namco's Neck -> Head along local X) cannot tell two
    reflections apart from its offsets; it takes its parent's, so a straight neck stays straight."""
    sk = Skeleton(names=("Hips", "Chest", "Neck", "Head", "Arm_L", "Arm_R"), parents=np.array([-1, 0, 1, 2, 1, 1]),
                  offsets=np.array([[0, 90.0, 0], [10, 0, 0], [15, 0, 0], [6, 0, 0], [12, 0, 5], [12, 0, -5]]))
    frames = K.mirror_frames(sk)
    np.testing.assert_array_equal(np.diag(frames[1]), [1, 1, -1])  # arms at +-Z in the chest frame
    np.testing.assert_array_equal(frames[2], frames[1])  # tie between Y and Z: the parent's Z
    np.testing.assert_array_equal(frames[3], frames[2])
    ident = np.zeros((1, 6, 4))
    ident[..., 0] = 1.0
    m = Motion(sk, ident, sk.offsets[None].copy(), fps=30)
    assert R.quat_angle(K.mirror(m).rotations[0, 2]) < 1e-12  # the neck is not turned by 180 deg


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_yaw_removal_then_restore_is_identity(seed):
    m = random_motion(np.random.default_rng(seed), sym_skeleton())
    m2, yaw = RM.remove_root_yaw(m)
    back = RM.restore_root_yaw(m2, yaw)
    np.testing.assert_allclose(K.forward_kinematics(back), K.forward_kinematics(m), atol=1e-9)
    # After removal the hips' world rotation has no twist about the vertical axis.
    g = K.global_rotations(m2)[:, 0]
    _, twist = RM.swing_twist(R.quat_inv(g), np.array([0.0, 1.0, 0.0]))
    assert R.quat_angle(twist).max() < 1e-6
    # yaw is a pure rotation about +Y
    np.testing.assert_allclose(yaw[:, [1, 3]], 0, atol=1e-12)


def test_floor_contact_puts_lowest_foot_on_floor():
    m = random_motion(np.random.default_rng(1), sym_skeleton())
    f = RM.floor_contact(m)
    pos = K.forward_kinematics(f)
    feet = RM.foot_joints(m.skeleton)
    assert feet == [3, 5]
    np.testing.assert_allclose(pos[:, feet, 1].min(axis=1), 0, atol=1e-9)
    # Only heights change.
    np.testing.assert_allclose(pos[..., [0, 2]], K.forward_kinematics(m)[..., [0, 2]], atol=1e-9)


def test_velocities_of_constant_motion():
    x = np.arange(10.0)[:, None, None] * np.array([1.0, 2.0, 0.0])
    v = K.joint_velocities(x, fps=30)
    np.testing.assert_allclose(v, np.broadcast_to([30.0, 60.0, 0.0], v.shape))


@pytest.mark.realdata
def test_real_files_mirror_and_yaw(bandai_dir, zeggs_dir):
    for f in [sorted(bandai_dir.glob("*.bvh"))[0], zeggs_dir / "067_Speech_2_x_1_0.bvh"]:
        m = bvh.load(f)
        p = K.forward_kinematics(m)
        perm = K.mirror_pairs(m.skeleton)
        assert (perm != np.arange(len(perm))).sum() >= 8
        reflected = p[:, perm] * [-1, 1, 1]
        exact = K.mirror(m, keep_rig_offsets=False)
        np.testing.assert_allclose(K.forward_kinematics(exact), reflected, atol=1e-6)
        # Default: the rig's own bone lengths (a saveable pose); positions within the rig's asymmetry.
        mirrored = K.mirror(m)
        rot_only = [j for j, c in enumerate(m.skeleton.channels) if len(c) == 3]
        np.testing.assert_array_equal(mirrored.translations[:, rot_only], m.translations[:, rot_only])
        assert np.abs(K.forward_kinematics(mirrored) - reflected).max() < 4.0  # ZEGGS: 3.6 cm at fingertips
        m2, yaw = RM.remove_root_yaw(m)
        np.testing.assert_allclose(K.forward_kinematics(RM.restore_root_yaw(m2, yaw)), p, atol=1e-6)
    bn = bvh.load(sorted(bandai_dir.glob("*.bvh"))[0])
    # Bandai-Namco's rig is symmetric to 0.05 cm: mirrored local translations stay at the rest offsets.
    assert np.abs(K.mirror(bn).translations[:, 2:] - bn.skeleton.offsets[2:]).max() < 0.05


def _chordal_mean(q):
    u, _, vt = np.linalg.svd(R.quat_to_matrix(q).mean(0))
    return R.matrix_to_quat(u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt)


@pytest.mark.realdata
def test_real_mirror_in_the_originals_representation(bandai_dir, zeggs_dir):
    """The TGST data pipeline's mirror (rig T-pose as the symmetric reference): (a) world positions reflected
    with L/R swapped to 1e-6 cm, (b) per joint, the mean local rotation of the mirrored clip lies within a
    few degrees of the original's (the offsets-only mirror puts the shoulders 180 deg away); on ZEGGS
    (rest pose = T-pose) it is the offsets-only mirror."""
    from jaxgest.motion import body
    from jaxgest.tgst.data import mirror_motion

    m = bvh.load(bandai_dir / "dataset-1_walk_normal_001.bvh")  # a nearly symmetric motion
    mm = mirror_motion(m)
    reflected = K.forward_kinematics(m)[:, K.mirror_pairs(m.skeleton)] * [-1, 1, 1]
    np.testing.assert_allclose(K.forward_kinematics(mm), reflected, atol=1e-6)
    gap = {}
    for name in body.BODY:
        j = m.skeleton.index(name)
        a, b = _chordal_mean(m.rotations[:, j]), _chordal_mean(mm.rotations[:, j])
        gap[name] = float(np.degrees(R.quat_angle(R.quat_mul(R.quat_inv(a), b))))
    old = K.mirror(m)  # offsets-only: same positions, the shoulders' frames turned by 180 deg
    j = m.skeleton.index("Shoulder_L")
    old_gap = np.degrees(R.quat_angle(R.quat_mul(R.quat_inv(_chordal_mean(m.rotations[:, j])),
                                                 _chordal_mean(old.rotations[:, j]))))
    assert old_gap > 90, old_gap
    assert max(gap[n] for n in ("Hips", "Spine", "Chest", "Neck", "Head")) < 10.0, gap  # 1-8 deg
    assert max(gap[n] for n in body.ARMS) < 10.0, gap  # 3.5-6 deg
    assert max(gap.values()) < 20.0, gap  # feet 14 deg
    z = bvh.load(zeggs_dir / "067_Speech_2_x_1_0.bvh")
    z = z.replace(rotations=z.rotations[:60], translations=z.translations[:60])
    np.testing.assert_allclose(mirror_motion(z).rotations, K.mirror(z).rotations, atol=1e-12)


def test_fk_chain_with_root_rotation_and_translation_channels():
    sk = chain()
    rot = np.zeros((1, 3, 4))
    rot[..., 0] = 1
    rot[0, 0] = R.euler_to_quat(np.array([90.0, 0, 0]), "YXZ")  # root turns 90 deg about Y
    rot[0, 1] = R.euler_to_quat(np.array([90.0, 0, 0]), "XYZ")  # spine pitches 90 deg about X
    trans = np.broadcast_to(sk.offsets, (1, 3, 3)).copy()
    trans[0, 1] = [0, 10, 3]  # a joint with its own position channels
    pos = K.forward_kinematics(Motion(sk, rot, trans, fps=30))
    # Ry(90): x -> -z, z -> x.  Head offset (0, 20, 0) pitched about X -> (0, 0, 20) -> world (20, 0, 0).
    np.testing.assert_allclose(pos[0], [[0, 100, 0], [3, 110, 0], [23, 110, 0]], atol=1e-12)


def test_jnp_fk_batched_jit_on_body_matches_numpy():
    from jaxgest.motion.body import body_skeleton

    sk = body_skeleton()
    rng = np.random.default_rng(2)
    ms = [random_motion(rng, sk, F=4) for _ in range(2)]
    rot = jnp.asarray(np.stack([m.rotations for m in ms]), jnp.float32)  # (B, F, J, 4)
    trans = jnp.asarray(np.stack([m.translations for m in ms]), jnp.float32)
    f = jax.jit(lambda r, t: K.fk_positions(r, t, tuple(int(p) for p in sk.parents)))
    out = np.asarray(f(rot, trans))
    assert out.shape == (2, 4, 21, 3)
    for b, m in enumerate(ms):
        np.testing.assert_allclose(out[b], K.forward_kinematics(m), atol=2e-3)


def test_mirror_pairs_by_name():
    names = ("Hips", "UpperArm_L", "UpperArm_R", "LeftHand", "RightHand", "mixamorig:LeftFoot",
             "mixamorig:RightFoot", "Lonely_L", "Spine")
    sk = Skeleton(names=names, parents=np.array([-1, 0, 0, 0, 0, 0, 0, 0, 0]), offsets=np.zeros((9, 3)))
    perm = K.mirror_pairs(sk)
    np.testing.assert_array_equal(perm, [0, 2, 1, 4, 3, 6, 5, 7, 8])
    np.testing.assert_array_equal(perm[perm], np.arange(9))


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(-179.0, 179.0))
def test_yaw_removal_is_invariant_to_turning_the_whole_motion(seed, angle):
    """Turning a motion about the vertical axis changes only the removed yaw, not the yaw-free motion."""
    m = random_motion(np.random.default_rng(seed), sym_skeleton())
    turn = R.euler_to_quat(np.array([angle, 0.0, 0.0]), "YXZ")
    rot = m.rotations.copy()
    rot[:, 0] = R.quat_mul(turn, rot[:, 0])
    trans = m.translations.copy()
    trans[:, 0] = R.quat_rotate(turn, trans[:, 0])
    turned = m.replace(rotations=rot, translations=trans)
    a, yaw_a = RM.remove_root_yaw(m)
    b, yaw_b = RM.remove_root_yaw(turned)
    np.testing.assert_allclose(K.forward_kinematics(b), K.forward_kinematics(a), atol=1e-9)
    expected = R.quat_mul(turn[None], yaw_a)
    assert R.quat_angle(R.quat_mul(R.quat_inv(expected), yaw_b)).max() < 1e-9


def test_floor_contact_without_feet_is_a_clear_error():
    from jaxgest.runtime.errors import DataError

    m = random_motion(np.random.default_rng(0), chain())
    with pytest.raises(DataError, match="no foot/toe joints"):
        RM.floor_contact(m)


def _scipy_fk(m):
    """Independent FK: scipy rotations composed as matrices, no jaxgest rotation code."""
    Rotation = pytest.importorskip("scipy.spatial.transform").Rotation
    F, J = m.rotations.shape[:2]
    mats = Rotation.from_quat(m.rotations.reshape(-1, 4)[:, [1, 2, 3, 0]]).as_matrix().reshape(F, J, 3, 3)
    gm = np.empty_like(mats)
    gp = np.empty((F, J, 3))
    for j, p in enumerate(m.skeleton.parents):
        if p < 0:
            gm[:, j], gp[:, j] = mats[:, j], m.translations[:, j]
        else:
            gm[:, j] = gm[:, p] @ mats[:, j]
            gp[:, j] = gp[:, p] + np.einsum("fij,fj->fi", gm[:, p], m.translations[:, j])
    return gp


@pytest.mark.realdata
def test_fk_matches_scipy_on_real_files_and_floor_contact(bandai_dir, zeggs_dir):
    for f in [bandai_dir / "dataset-1_bow_active_001.bvh", zeggs_dir / "067_Speech_2_x_1_0.bvh"]:
        m = bvh.load(f)
        m = m.replace(rotations=m.rotations[:300], translations=m.translations[:300])
        np.testing.assert_allclose(K.forward_kinematics(m), _scipy_fk(m), atol=1e-8)
        mm = K.mirror(K.mirror(m))
        assert R.quat_angle(R.quat_mul(R.quat_inv(mm.rotations), m.rotations)).max() < 1e-9
        np.testing.assert_allclose(mm.translations, m.translations, atol=1e-9)
        fl = RM.floor_contact(m)
        feet = RM.foot_joints(m.skeleton)
        np.testing.assert_allclose(K.forward_kinematics(fl)[:, feet, 1].min(axis=1), 0, atol=1e-9)


def test_jnp_fk_differentiable_and_traced_once():
    import chex

    sk = chain()
    parents = tuple(int(p) for p in sk.parents)

    def loss(r, t):
        return jnp.sum(K.fk_positions(r, t, parents)[..., 1])

    @jax.jit
    @chex.assert_max_traces(n=1)
    def grads(r, t):
        return jax.grad(loss, argnums=(0, 1))(r, t)

    rng = np.random.default_rng(5)
    for _ in range(2):
        m = random_motion(rng, sk, F=3)
        gr, gt = grads(jnp.asarray(m.rotations, jnp.float32), jnp.asarray(m.translations, jnp.float32))
        assert gr.shape == (3, 3, 4) and bool(jnp.all(jnp.isfinite(gr)))
        # d(sum of heights)/d(root height) = number of joints.
        np.testing.assert_allclose(gt[:, 0, 1], 3.0, rtol=1e-6)

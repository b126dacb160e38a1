"""ZeroEGGS pose features: layout, inversion, root integration, any skeleton."""

from __future__ import annotations

import numpy as np
import pytest

from jaxgest.motion import bvh
from jaxgest.motion import kinematics as K
from jaxgest.motion import rotations as R
from jaxgest.motion.synthetic import render_clip
from jaxgest.zeggs import features


@pytest.fixture(scope="module")
def synthetic_motion():
    m, _, _ = render_clip("greeting", "energetic", seed=1)
    return m


def check_inverts(m):
    out = features.extract_features(m)
    x = out["features"]
    layout = features.PoseLayout(m.skeleton.num_joints)
    assert x.shape == (m.num_frames, layout.size) and np.all(np.isfinite(x))
    pos, rot = features.integrate_root(x[:, layout.root_velocity].astype(np.float64),
                                 x[:, layout.root_angular_velocity].astype(np.float64), m.fps,
                                 out["root_position"][0], out["root_rotation"][0])
    np.testing.assert_allclose(pos, out["root_position"], atol=1e-3)
    assert R.quat_angle(R.quat_mul(R.quat_inv(rot), out["root_rotation"])).max() < 1e-4
    back = features.features_to_motion(x, m, out["root_position"], out["root_rotation"])
    np.testing.assert_allclose(K.forward_kinematics(back), K.forward_kinematics(m), atol=1e-3)
    return out


def test_synthetic_features_invert(synthetic_motion):
    out = check_inverts(synthetic_motion)
    # The root stands on the ground and faces +Z for the synthetic character.
    np.testing.assert_allclose(out["root_position"][:, 1], 0.0)
    fwd = R.quat_rotate(out["root_rotation"], np.array([0.0, 0.0, 1.0]))
    assert np.all(fwd[:, 2] > 0.9)


def test_root_rotation_follows_a_turn(synthetic_motion):
    m = synthetic_motion
    turn = R.euler_to_quat(np.array([0.0, 90.0, 0.0]), "XYZ")
    rot = m.rotations.copy()
    rot[:, 0] = R.quat_mul(turn, rot[:, 0])
    trans = m.translations.copy()
    trans[:, 0] = R.quat_rotate(turn, trans[:, 0])
    turned = m.replace(rotations=rot, translations=trans)
    a = features.extract_features(m)
    b = features.extract_features(turned)
    # Root-relative features do not change when the whole character turns; the root yaw does.
    np.testing.assert_allclose(a["features"], b["features"], atol=1e-3)
    delta = R.quat_angle(R.quat_mul(b["root_rotation"], R.quat_inv(a["root_rotation"])))
    np.testing.assert_allclose(np.degrees(delta), 90.0, atol=1e-3)


@pytest.mark.realdata
def test_real_rigs_invert(zeggs_dir, bandai_dir):
    z = check_inverts(bvh.load(zeggs_dir / "067_Speech_2_x_1_0.bvh"))
    assert z["features"].shape[1] == 15 * 75 + 6
    check_inverts(bvh.load(sorted(bandai_dir.glob("*.bvh"))[5]))


def _one_frame_template(m):
    """What generation writes onto: the rig's first frame repeated (no joint's translation animated)."""
    return m.replace(rotations=np.repeat(m.rotations[:1], m.num_frames, 0),
                     translations=np.repeat(m.translations[:1], m.num_frames, 0))


def _wrap_in_static_root(m):
    """``m`` under an extra static root joint (as Bandai-Namco's ``joint_Root`` above ``Hips``)."""
    from jaxgest.motion.skeleton import Skeleton

    sk = m.skeleton
    parents = np.concatenate([[-1], np.where(sk.parents < 0, 0, sk.parents + 1)])
    offsets = np.concatenate([np.zeros((1, 3)), sk.offsets])
    channels = (sk.channels[0],) + tuple(sk.channels)
    wsk = Skeleton(("wrapper_root",) + sk.names, parents, offsets, channels,
                   {k + 1: v for k, v in sk.end_sites.items()}, sk.up_axis)
    q0 = np.zeros((m.num_frames, 1, 4))
    q0[..., 0] = 1.0
    return m.replace(skeleton=wsk, rotations=np.concatenate([q0, m.rotations], 1),
                     translations=np.concatenate([np.zeros((m.num_frames, 1, 3)), m.translations], 1))


def check_one_frame_template_keeps_hips(m):
    out = features.extract_features(m)
    back = features.features_to_motion(out["features"], _one_frame_template(m), out["root_position"],
                                       out["root_rotation"])
    err = np.abs(K.forward_kinematics(back) - K.forward_kinematics(m)).max()
    assert err < 1e-3, err
    return back


def test_static_wrapper_root_keeps_hips_translation(synthetic_motion):
    """A static wrapper root must not freeze the hips (fails when the template decides what is animated)."""
    wrapped = _wrap_in_static_root(synthetic_motion)
    assert features.translated_joints(wrapped.skeleton) == (0, 1)
    assert features.translated_joints(synthetic_motion.skeleton) == (0,)
    # The hips move in this clip (else the check below could not fail).
    assert wrapped.translations[:, 1].std(0).max() > 0.1
    check_one_frame_template_keeps_hips(synthetic_motion)
    back = check_one_frame_template_keeps_hips(wrapped)
    np.testing.assert_allclose(back.translations[:, 0], 0.0, atol=1e-6)  # the wrapper stays where it is


@pytest.mark.realdata
def test_bandai_one_frame_template_keeps_hips(bandai_dir):
    m = bvh.load(sorted(bandai_dir.glob("*.bvh"))[5])
    sk = m.skeleton
    assert [sk.names[j] for j in features.translated_joints(sk)] == ["joint_Root", "Hips"]
    assert m.translations[:, sk.index("Hips")].std(0).max() > 1.0
    check_one_frame_template_keeps_hips(m)


def test_fk_positions_of_target_features_equal_their_positions(synthetic_motion):
    """FK of the root-frame rotations with the rig's offsets gives back the root-frame positions (the loss's
    FK is what features_to_motion renders), also under a static wrapper root."""
    import jax.numpy as jnp

    from jaxgest.zeggs import losses
    from jaxgest.zeggs.config import preset

    for m in (synthetic_motion, _wrap_in_static_root(synthetic_motion)):
        J = m.skeleton.num_joints
        cfg = preset("tiny", num_joints=J, **features.fk_fields(m.skeleton)).model
        x = features.extract_features(m)["features"]
        lay = features.PoseLayout(J)
        rot = jnp.asarray(x[:, lay.local_rotations].reshape(-1, J, 6))
        pos = jnp.asarray(x[:, lay.local_positions].reshape(-1, J, 3))
        fk = np.asarray(losses.forward_kinematics(rot, pos, cfg))
        np.testing.assert_allclose(fk, np.asarray(pos), atol=2e-3)
        # Only the translated joints are read from `pos`: moving the others' channels changes nothing,
        # moving the hips' moves the whole body.
        other = np.setdiff1d(np.arange(J), features.translated_joints(m.skeleton))
        np.testing.assert_allclose(losses.forward_kinematics(rot, pos.at[:, other].add(50.0), cfg), fk, atol=1e-4)
        hips = features.translated_joints(m.skeleton)[-1]
        moved = np.asarray(losses.forward_kinematics(rot, pos.at[:, hips].add(jnp.array([0.0, 0.0, 5.0])), cfg))
        np.testing.assert_allclose(moved[:, other] - fk[:, other], np.broadcast_to([0, 0, 5.0], moved[:, other].shape),
                                   atol=1e-4)


@pytest.mark.realdata
def test_fk_positions_on_bandai(bandai_dir):
    import jax.numpy as jnp

    from jaxgest.zeggs import losses
    from jaxgest.zeggs.config import preset

    m = bvh.load(sorted(bandai_dir.glob("*.bvh"))[5])
    m = m.replace(rotations=m.rotations[:200], translations=m.translations[:200])
    J = m.skeleton.num_joints
    cfg = preset("tiny", num_joints=J, **features.fk_fields(m.skeleton)).model
    x = features.extract_features(m)["features"]
    lay = features.PoseLayout(J)
    pos = x[:, lay.local_positions].reshape(-1, J, 3)
    fk = losses.forward_kinematics(jnp.asarray(x[:, lay.local_rotations].reshape(-1, J, 6)), jnp.asarray(pos), cfg)
    np.testing.assert_allclose(np.asarray(fk), pos, atol=5e-3)


def _zeggs_named_rig(leg_scale: float = 1.3):
    """A one-frame template on a 21-joint rig named as the ZEGGS map names the body joints, in the T-pose at
    rest (the ZEGGS map's convention), with legs ``leg_scale`` times the body's."""
    from jaxgest.motion import body
    from jaxgest.motion.retarget import rest_positions
    from jaxgest.motion.skeleton import Motion, Skeleton

    bsk = body.body_skeleton()
    world = rest_positions(bsk, body.body_tpose())
    offsets = world - np.where(bsk.parents[:, None] >= 0, world[np.maximum(bsk.parents, 0)], 0.0)
    legs = [bsk.index(n) for n in body.LOWER]
    offsets[legs] *= leg_scale
    jm = body.load_map("zeggs")["joints"]
    sk = Skeleton(tuple(jm[n] for n in bsk.names), bsk.parents, offsets)
    ident = np.zeros((1, sk.num_joints, 4))
    ident[..., 0] = 1.0
    return Motion(sk, ident, offsets[None].copy(), 60.0), [sk.index(jm[n]) for n in body.FEET]


def test_rig_transfer_is_identity_on_the_same_rig_and_stands_on_the_floor_on_another(synthetic_motion):
    """motion.body.to_rig (the one rig transfer of pipeline and ZeroEGGS inference): the motion itself on
    its own rig; on another rig (ZEGGS joint names, legs 30 % longer) through the body maps with the lowest
    foot on the floor every frame, which the plain body retarget does not give."""
    from jaxgest.motion import body
    from jaxgest.motion.body import to_rig

    m = synthetic_motion
    assert to_rig(m, m) is m
    template, feet = _zeggs_named_rig()
    up = template.skeleton.up_axis
    out = to_rig(m, template)
    assert out.skeleton.names == template.skeleton.names and out.num_frames == m.num_frames and out.name == m.name
    np.testing.assert_allclose(K.forward_kinematics(out)[:, feet, up].min(1), 0.0, atol=1e-6)
    plain = body.retarget_from_body(body.retarget_to_body(m), template)
    assert np.abs(K.forward_kinematics(plain)[:, feet, up].min(1)).max() > 1.0
    back = to_rig(out, m)  # and back onto the body rig: on the floor too
    body_feet = [m.skeleton.index(n) for n in body.FEET]
    np.testing.assert_allclose(K.forward_kinematics(back)[:, body_feet, up].min(1), 0.0, atol=1e-6)
    short = to_rig(m, template, fps=30.0, frames=m.num_frames // 2 - 1)
    assert short.fps == 30.0 and short.num_frames == m.num_frames // 2 - 1

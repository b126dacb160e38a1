"""ZeroEGGS pose features: layout, inversion, root integration, any skeleton."""

from __future__ import annotations

import numpy as np
import pytest

from jaxgest.motion import bvh
from jaxgest.motion import kinematics as K
from jaxgest.motion import rotations as R
from jaxgest.motion.synthetic import render_clip
from jaxgest.zeggs import features as Fe


@pytest.fixture(scope="module")
def synthetic_motion():
    m, _, _ = render_clip("greeting", "energetic", seed=1)
    return m


def check_inverts(m):
    out = Fe.extract_features(m)
    x = out["features"]
    layout = Fe.PoseLayout(m.skeleton.num_joints)
    assert x.shape == (m.num_frames, layout.size) and np.all(np.isfinite(x))
    pos, rot = Fe.integrate_root(x[:, layout.root_velocity].astype(np.float64),
                                 x[:, layout.root_angular_velocity].astype(np.float64), m.fps,
                                 out["root_position"][0], out["root_rotation"][0])
    np.testing.assert_allclose(pos, out["root_position"], atol=1e-3)
    assert R.quat_angle(R.quat_mul(R.quat_inv(rot), out["root_rotation"])).max() < 1e-4
    back = Fe.features_to_motion(x, m, out["root_position"], out["root_rotation"])
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
    a = Fe.extract_features(m)
    b = Fe.extract_features(turned)
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
    out = Fe.extract_features(m)
    back = Fe.features_to_motion(out["features"], _one_frame_template(m), out["root_position"],
                                 out["root_rotation"])
    err = np.abs(K.forward_kinematics(back) - K.forward_kinematics(m)).max()
    assert err < 1e-3, err
    return back


def test_static_wrapper_root_keeps_hips_translation(synthetic_motion):
    """A static wrapper root must not freeze the hips (fails when the template decides what is animated)."""
    wrapped = _wrap_in_static_root(synthetic_motion)
    assert Fe.translated_joints(wrapped.skeleton) == (0, 1)
    assert Fe.translated_joints(synthetic_motion.skeleton) == (0,)
    # The hips move in this clip (else the check below could not fail).
    assert wrapped.translations[:, 1].std(0).max() > 0.1
    check_one_frame_template_keeps_hips(synthetic_motion)
    back = check_one_frame_template_keeps_hips(wrapped)
    np.testing.assert_allclose(back.translations[:, 0], 0.0, atol=1e-6)  # the wrapper stays where it is


@pytest.mark.realdata
def test_bandai_one_frame_template_keeps_hips(bandai_dir):
    m = bvh.load(sorted(bandai_dir.glob("*.bvh"))[5])
    sk = m.skeleton
    assert [sk.names[j] for j in Fe.translated_joints(sk)] == ["joint_Root", "Hips"]
    assert m.translations[:, sk.index("Hips")].std(0).max() > 1.0
    check_one_frame_template_keeps_hips(m)


def test_fk_positions_of_target_features_equal_their_positions(synthetic_motion):
    """FK of the root-frame rotations with the rig's offsets gives back the root-frame positions (the loss's
    FK is what features_to_motion renders), also under a static wrapper root."""
    import jax.numpy as jnp

    from jaxgest.zeggs import losses as L
    from jaxgest.zeggs.config import get_config

    for m in (synthetic_motion, _wrap_in_static_root(synthetic_motion)):
        J = m.skeleton.num_joints
        cfg = get_config("tiny", num_joints=J, **Fe.fk_fields(m.skeleton))
        x = Fe.extract_features(m)["features"]
        lay = Fe.PoseLayout(J)
        rot = jnp.asarray(x[:, lay.local_rotations].reshape(-1, J, 6))
        pos = jnp.asarray(x[:, lay.local_positions].reshape(-1, J, 3))
        fk = np.asarray(L.forward_kinematics(rot, pos, cfg))
        np.testing.assert_allclose(fk, np.asarray(pos), atol=2e-3)
        # Only the translated joints are read from `pos`: moving the others' channels changes nothing,
        # moving the hips' moves the whole body.
        other = np.setdiff1d(np.arange(J), Fe.translated_joints(m.skeleton))
        np.testing.assert_allclose(L.forward_kinematics(rot, pos.at[:, other].add(50.0), cfg), fk, atol=1e-4)
        hips = Fe.translated_joints(m.skeleton)[-1]
        moved = np.asarray(L.forward_kinematics(rot, pos.at[:, hips].add(jnp.array([0.0, 0.0, 5.0])), cfg))
        np.testing.assert_allclose(moved[:, other] - fk[:, other], np.broadcast_to([0, 0, 5.0], moved[:, other].shape),
                                   atol=1e-4)


@pytest.mark.realdata
def test_fk_positions_on_bandai(bandai_dir):
    import jax.numpy as jnp

    from jaxgest.zeggs import losses as L
    from jaxgest.zeggs.config import get_config

    m = bvh.load(sorted(bandai_dir.glob("*.bvh"))[5])
    m = m.replace(rotations=m.rotations[:200], translations=m.translations[:200])
    J = m.skeleton.num_joints
    cfg = get_config("tiny", num_joints=J, **Fe.fk_fields(m.skeleton))
    x = Fe.extract_features(m)["features"]
    lay = Fe.PoseLayout(J)
    pos = x[:, lay.local_positions].reshape(-1, J, 3)
    fk = L.forward_kinematics(jnp.asarray(x[:, lay.local_rotations].reshape(-1, J, 6)), jnp.asarray(pos), cfg)
    np.testing.assert_allclose(np.asarray(fk), pos, atol=5e-3)

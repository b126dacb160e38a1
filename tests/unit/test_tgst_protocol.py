"""The authors' evaluation protocol (SPEC §5) and the fast evaluation path of jaxgest.tgst.evaluate.

Root-local positions, forward differences, the mirrored style reference, the one-frame-spike bound of the
style error, swap diagnostics, length buckets and the batched transfers against model.transfer.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest import metrics
from jaxgest.motion import bvh, kinematics, root_motion
from jaxgest.motion.synthetic import render_clip
from jaxgest.tgst import evaluate as ev
from jaxgest.tgst.data import mirror_motion


@pytest.fixture(scope="module")
def clip():
    return render_clip("greeting", "energetic", fps=60.0)[0]


# --------------------------------------------------------------------------------------------------------
# velocities


@settings(max_examples=40, deadline=None)
@given(
    frames=st.integers(2, 60),
    fps=st.sampled_from([24.0, 29.97, 30.0, 60.0, 120.0]),
    speed=st.lists(st.floats(-500, 500, allow_nan=False), min_size=3, max_size=3),
    start=st.lists(st.floats(-200, 200, allow_nan=False), min_size=3, max_size=3),
)
def test_forward_differences_of_constant_speed_are_exact_at_both_ends(frames, fps, speed, start):
    u, p0 = np.array(speed), np.array(start)
    pos = (p0 + (np.arange(frames) / fps)[:, None] * u)[:, None, :]  # (F, 1, 3)
    v = kinematics.forward_differences(pos, fps)
    assert v.shape == (frames - 1, 1, 3)
    tol = 1e-9 * (1 + np.abs(p0).max() + np.abs(u).max()) * fps
    np.testing.assert_allclose(v[0, 0], u, atol=tol)  # first frame
    np.testing.assert_allclose(v[-1, 0], u, atol=tol)  # last frame
    np.testing.assert_allclose(v[:, 0], np.broadcast_to(u, (frames - 1, 3)), atol=tol)
    flat = metrics.arm_velocities(np.repeat(pos, 2, axis=1), fps, [1, 0], forward=True)
    np.testing.assert_allclose(flat, np.tile(u, (frames - 1, 2)), atol=tol)


def test_constant_speed_clip_features_at_both_ends(clip):
    """A held pose carried at constant speed (and turning at a constant rate): the world positions move at
    exactly that speed from the first to the last velocity; root-local positions do not move at all."""
    F, fps = 90, clip.fps
    still = clip.replace(rotations=np.repeat(clip.rotations[:1], F, 0), translations=np.repeat(clip.translations[:1], F, 0))
    u = np.array([80.0, 0.0, -45.0])  # cm/s
    moved = root_motion.set_root_position(still, kinematics.forward_kinematics(still)[:, 0] + (np.arange(F) / fps)[:, None] * u)
    world_fwd = ev.Protocol("world-fwd", root_local=False, trim_seconds=0.0, forward_differences=True,
                            mirror_style=False)
    _, arms = ev.clip_features(moved, protocol=world_fwd)
    assert arms.shape == (F - 1, 24)
    np.testing.assert_allclose(arms, np.tile(u * 0.01, (F - 1, 8)), atol=1e-9)
    # root-local (authors): translation and a constant-rate turn of the root leave no velocity, ends included
    half = np.arange(F) * 0.025  # 0.05 rad per frame about +Y
    yaw = np.stack([np.cos(half), np.zeros(F), np.sin(half), np.zeros(F)], -1)
    turned = root_motion.restore_root_yaw(moved, yaw)
    no_cut = ev.get_protocol("authors", trim_seconds=0.0)
    _, local = ev.clip_features(turned, protocol=no_cut)
    np.testing.assert_allclose(local, 0.0, atol=1e-9)
    _, world = ev.clip_features(turned, protocol="world")
    assert np.abs(world).max() > 0.5  # the world protocol sees the root's path and turn


# --------------------------------------------------------------------------------------------------------
# one-frame spike: a stated bound on the change of E_style


def _spike_bound(d: np.ndarray, fps: float, window: int) -> float:
    """Per-window bound: fps * sum_j ||d_j|| * (1 / theta + sqrt(2 / theta)).

    A displacement d_j of joint j on one frame changes at most two forward-difference velocities (by
    +-d_j fps); within one window the mean moves by at most ||d_j|| fps / theta and every per-channel
    population std by at most std(e) (std is a seminorm), so the per-joint std vector by at most
    sqrt(2 / theta) ||d_j|| fps; the min over style windows is 1-Lipschitz.
    """
    return fps * np.linalg.norm(d, axis=-1).sum() * (1.0 / window + math.sqrt(2.0 / window))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    frames=st.integers(70, 220),
    where=st.floats(0.0, 1.0),
    size=st.floats(0.001, 0.2),
)
def test_one_frame_spike_changes_style_error_by_at_most_the_stated_bound(seed, frames, where, size):
    """E_style under the authors' protocol (forward differences, no repeated frame): a one-frame spike
    anywhere, first and last frames included, changes each window's error by at most
    fps * sum_j ||d_j|| * (1/theta + sqrt(2/theta)) (0.19 fps sum_j ||d_j|| at theta = 64) and the mean over
    K windows by at most 3/K of that (the two touched velocities lie in at most 3 half-overlapped windows)."""
    rng = np.random.default_rng(seed)
    fps, window = 30.0, 64
    pos = np.cumsum(rng.normal(scale=0.004, size=(frames, 8, 3)), axis=0)  # metres, smooth-ish random walk
    ref = np.cumsum(rng.normal(scale=0.006, size=(150, 8, 3)), axis=0)
    t = int(round(where * (frames - 1)))
    d = rng.normal(size=(8, 3))
    d *= size / np.linalg.norm(d, axis=-1).max()
    spiked = pos.copy()
    spiked[t] += d
    vel = lambda p: metrics.arm_velocities(p, fps, range(8), forward=True)  # noqa: E731
    ref_v = vel(ref)
    base, hit = metrics.style_error(vel(pos), ref_v, window), metrics.style_error(vel(spiked), ref_v, window)
    k = len(metrics.window_statistics(vel(pos), window)[0])
    bound = _spike_bound(d, fps, window)
    assert abs(hit["worst"] - base["worst"]) <= bound + 1e-9
    assert abs(hit["w25"] - base["w25"]) <= bound + 1e-9
    assert abs(hit["mean"] - base["mean"]) <= min(3, k) / k * bound + 1e-9


def test_world_protocol_counts_a_first_frame_spike_twice():
    """The backward differences of the world protocol repeat v[1] as v[0]; forward differences do not."""
    pos = np.zeros((10, 1, 3))
    pos[0, 0, 0] = 1.0  # a spike on the first frame
    back = metrics.arm_velocities(pos, 30.0, [0])
    fwd = metrics.arm_velocities(pos, 30.0, [0], forward=True)
    assert np.count_nonzero(back[:, 0]) == 2 and np.count_nonzero(fwd[:, 0]) == 1


# --------------------------------------------------------------------------------------------------------
# root-local positions and the mirrored style reference


def test_root_local_positions_are_fk_with_the_root_reset(clip):
    """Authors' get_joint_positions(root_positions=None): root at the origin, root rotation identity."""
    assert clip.skeleton.parents[0] == -1 and clip.skeleton.names[0] == "Hips"
    reset = clip.replace(
        rotations=np.concatenate([np.tile([1.0, 0, 0, 0], (clip.num_frames, 1, 1)), clip.rotations[:, 1:]], 1),
        translations=np.concatenate([np.zeros((clip.num_frames, 1, 3)), clip.translations[:, 1:]], 1),
    )
    local = kinematics.root_local_positions(clip)
    np.testing.assert_allclose(local, kinematics.forward_kinematics(reset), atol=1e-9)
    # a rigid turn and shift of the whole clip changes world positions, not root-local ones
    turned = root_motion.restore_root_yaw(clip, np.tile([math.cos(0.6), 0, math.sin(0.6), 0], (clip.num_frames, 1)))
    turned = root_motion.set_root_position(turned, kinematics.forward_kinematics(turned)[:, 0] + [50.0, 0, -20])
    np.testing.assert_allclose(kinematics.root_local_positions(turned), local, atol=1e-8)
    assert np.abs(kinematics.forward_kinematics(turned) - kinematics.forward_kinematics(clip)).max() > 10


@pytest.mark.realdata
def test_root_local_positions_on_bandai_reset_root_and_hips(bandai_dir):
    m = bvh.load(bandai_dir / "dataset-1_bow_normal_001.bvh")
    assert m.skeleton.names[:2] == ("joint_Root", "Hips")
    rot, tr = m.rotations.copy(), m.translations.copy()
    rot[:, :2] = [1.0, 0, 0, 0]
    tr[:, :2] = 0.0
    # every joint from the hips down (joint_Root, above the hips, is a static wrapper the metrics never use)
    np.testing.assert_allclose(kinematics.root_local_positions(m)[:, 1:],
                               kinematics.forward_kinematics(m.replace(rotations=rot, translations=tr))[:, 1:],
                               atol=1e-6)


def test_style_reference_is_the_clip_then_its_mirror(clip):
    ref = ev.style_reference(clip)
    n = 30  # 0.5 s at 60 fps (the authors' 30 frames at 60 fps)
    mirror = mirror_motion(clip)  # the training data's mirror (rig T-pose)
    assert ref.num_frames == 2 * clip.num_frames - n
    np.testing.assert_array_equal(ref.rotations[: clip.num_frames - n], clip.rotations[: clip.num_frames - n])
    np.testing.assert_array_equal(ref.rotations[clip.num_frames:], mirror.rotations[n:])
    # the blend starts at the clip and moves toward the mirror's first frames
    np.testing.assert_allclose(ref.rotations[clip.num_frames - n], clip.rotations[clip.num_frames - n])
    assert ev.style_reference(clip, "world") is clip


# --------------------------------------------------------------------------------------------------------
# swap diagnostics and buckets


def test_swap_diagnostics_of_known_weights():
    eye = np.eye(10)
    d = ev.swap_diagnostics(eye)
    assert d["max_weight"] == 1.0 and d["effective_tokens"] == 1.0 and d["argmax_within_1"] == 1.0
    assert d["chance_within_1"] == pytest.approx((2 * 2 + 8 * 3) / 10 / 10)  # the two end rows have 2 neighbours
    uniform = ev.swap_diagnostics(np.full((6, 12), 1 / 12))
    assert uniform["max_weight"] == pytest.approx(1 / 12) and uniform["effective_tokens"] == pytest.approx(12)
    far = np.zeros((4, 20))
    far[:, 15] = 1.0
    assert ev.swap_diagnostics(far)["argmax_within_1"] == 0.0
    # queries past num_queries and padding columns past num_style
    w = np.zeros((5, 8))
    w[np.arange(5), [0, 1, 2, 7, 7]] = 1.0
    d = ev.swap_diagnostics(w, num_queries=3, num_style=6)
    assert d["num_queries"] == 3 and d["argmax_within_1"] == 1.0 and d["padding_mass"] == 0.0
    assert ev.swap_diagnostics(w, num_style=6)["padding_mass"] == pytest.approx(2 / 5)


@settings(max_examples=60, deadline=None)
@given(frames=st.integers(1, 20_000), ratio=st.sampled_from([1.1, 1.25, 1.5, 2.0]))
def test_bucket_length_holds_the_clip_with_bounded_padding(frames, ratio):
    b = ev.bucket_length(frames, ratio)
    assert b >= frames and b % 16 == 0 and b < max(64, ratio * frames + 16) + 1e-9
    assert ev.bucket_length(frames, 1.0) == frames


def test_few_buckets_over_a_range_of_lengths():
    assert len({ev.bucket_length(f, 1.25) for f in range(40, 4000)}) <= 20


def test_first_frame_spike_of_a_transfer_is_cut_by_the_authors_protocol(clip):
    """Motion level: a wild first frame (the clip-start artefact) changes no error under the authors'
    protocol (inside the 1 s cut) while the world protocol counts it (twice, as v[0] = v[1])."""
    style = render_clip("directions", "sad", fps=60.0)[0]
    rot = clip.rotations.copy()
    arm = clip.skeleton.index("UpperArm_R")
    rot[0, arm] = [0.0, 1.0, 0.0, 0.0]  # 180 degrees about x on the first frame only
    spiked = clip.replace(rotations=rot)
    a = ev.clip_errors(clip, clip, style, protocol="authors")
    b = ev.clip_errors(spiked, clip, style, protocol="authors")
    assert a == b
    a = ev.clip_errors(clip, clip, style, protocol="world")
    b = ev.clip_errors(spiked, clip, style, protocol="world")
    assert b["style"]["worst"] > a["style"]["worst"] and b["content"]["worst"] > a["content"]["worst"]

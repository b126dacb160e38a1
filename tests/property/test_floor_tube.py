"""Floor contact in a tube (kinematics.taut_string / floor_contact_tube, tgst.api.content_floor_contact)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.motion import kinematics as K

from jaxgest.motion import root_motion as RM
from jaxgest.motion import rotations as R
from jaxgest.motion.skeleton import Motion, Skeleton


def legged_skeleton(wrapper: bool = False) -> Skeleton:
    """Hips with two legs (foot + toe each) and a spine; optionally under a static ``joint_Root`` wrapper."""
    names = ["Hips", "Spine", "UpperLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "Foot_R", "Toes_R"]
    parents = [-1, 0, 0, 2, 3, 0, 5, 6]
    offsets = [[0, 90.0, 0], [0, 10, 0], [10, -5, 0], [0, -80, 0], [0, -5, 10], [-10, -5, 0], [0, -80, 0],
               [0, -5, 10]]
    if wrapper:
        names = ["joint_Root"] + names
        parents = [-1] + [p + 1 for p in parents]
        offsets = [[0, 0, 0]] + offsets
    return Skeleton(names=tuple(names), parents=np.array(parents), offsets=np.array(offsets))


def wobbly_motion(rng, F: int, wrapper: bool = False) -> Motion:
    """Legs that bend a little from frame to frame (the lowest foot joint's height wobbles)."""
    sk = legged_skeleton(wrapper)
    J = sk.num_joints
    rot = np.zeros((F, J, 4))
    rot[..., 0] = 1.0
    axes = rng.normal(size=(F, J, 3))
    angles = rng.uniform(0, 0.3, size=(F, J, 1))
    rot = R.quat_normalize(R.expmap_to_quat(axes / np.linalg.norm(axes, axis=-1, keepdims=True) * angles))
    if wrapper:  # a static parent turned away from the identity: the shift is expressed in its frame
        rot[:, 0] = R.euler_to_quat(np.array([90.0, 0.0, 0.0]), "XYZ")
        rot[:, 0] = R.quat_normalize(rot[:, 0])
    trans = np.broadcast_to(sk.offsets, (F, J, 3)).copy()
    h = 1 if wrapper else 0
    trans[:, h] += rng.normal(scale=3.0, size=(F, 3))
    return Motion(sk, rot, trans, fps=30)


def tv(x) -> float:
    return float(np.abs(np.diff(x)).sum())


def lowest(m: Motion) -> np.ndarray:
    return RM.lowest_foot_height(m)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 40), st.booleans())
def test_tolerance_zero_on_every_frame_is_floor_contact_exactly(seed, F, wrapper):
    rng = np.random.default_rng(seed)
    m = wobbly_motion(rng, F, wrapper)
    height = rng.normal(size=F)
    a = RM.floor_contact_tube(m, height=height, tolerance=0.0)
    b = RM.floor_contact(m, height=height)
    assert np.array_equal(a.translations, b.translations) and np.array_equal(a.rotations, m.rotations)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 50), st.sampled_from([0.0, 0.25, 0.5, 0.9, 3.0]),
       st.floats(0.0, 1.0), st.booleans())
def test_tube_holds_on_contact_frames_and_moves_least(seed, F, tol, p_contact, wrapper):
    """On contact frames the lowest foot is within tol of the target; only heights change; the shift's total
    variation (and its sum of squared steps) is never above the per-frame contact's."""
    rng = np.random.default_rng(seed)
    m = wobbly_motion(rng, F, wrapper)
    height = 4.25 + rng.normal(scale=0.5, size=F)
    contact = rng.random(F) < p_contact
    out = RM.floor_contact_tube(m, height=height, tolerance=tol, contact=contact)
    per_frame = RM.floor_contact(m, height=height)
    low = lowest(out)
    assert np.all(np.abs(low - height)[contact] <= tol + 1e-9)
    p0, p1 = K.forward_kinematics(m), K.forward_kinematics(out)
    np.testing.assert_allclose(p1[..., [0, 2]], p0[..., [0, 2]], atol=1e-9)  # only heights change
    shift = (p1[:, :, 1] - p0[:, :, 1])[:, int(wrapper):]  # the static wrapper stays
    np.testing.assert_allclose(shift, shift[:, :1].repeat(shift.shape[1], 1), atol=1e-9)  # rigid, vertical
    s_tube, s_frame = low - lowest(m), lowest(per_frame) - lowest(m)
    assert tv(s_tube) <= tv(s_frame) + 1e-9
    assert np.sum(np.diff(s_tube) ** 2) <= np.sum(np.diff(s_frame) ** 2) + 1e-9


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(3, 40), st.floats(0.0, 2.0))
def test_non_contact_frames_are_straight_lines_between_contact_frames(seed, F, tol):
    """Frames outside ``contact`` (the content in the air) get the straight line between the neighbouring
    contact frames' shifts, and the first / last contact frame's shift before / after them."""
    rng = np.random.default_rng(seed)
    m = wobbly_motion(rng, F)
    contact = rng.random(F) < 0.5
    contact[rng.integers(F)] = True
    out = RM.floor_contact_tube(m, height=0.0, tolerance=tol, contact=contact)
    shift = lowest(out) - lowest(m)
    on = np.flatnonzero(contact)
    np.testing.assert_allclose(shift, np.interp(np.arange(F), on, shift[on]), atol=1e-9)


def test_no_contact_frame_leaves_the_motion_as_it_is():
    m = wobbly_motion(np.random.default_rng(3), 12)
    out = RM.floor_contact_tube(m, height=0.0, tolerance=0.5, contact=np.zeros(12, bool))
    assert np.array_equal(out.translations, m.translations)


def test_taut_string_hand_cases():
    # a step inside the tube is absorbed (level path), a larger one is spread over the free frames
    lo, hi = np.array([0.0, 0, 0, 2, 2, 2]) - 0.5, np.array([0.0, 0, 0, 2, 2, 2]) + 0.5
    np.testing.assert_allclose(RM.taut_string(lo, hi), [0.5, 0.5, 0.5, 1.5, 1.5, 1.5])
    lo = np.array([0.0, -np.inf, -np.inf, -np.inf, 4.0])
    hi = np.array([0.0, np.inf, np.inf, np.inf, 4.0])
    np.testing.assert_allclose(RM.taut_string(lo, hi), [0, 1, 2, 3, 4])
    # a level path fits: the middle of the common interval
    np.testing.assert_allclose(RM.taut_string(np.array([0.0, 1.0]), np.array([3.0, 2.0])), [1.5, 1.5])
    # one-sided bounds
    np.testing.assert_allclose(RM.taut_string(np.array([1.0, -np.inf, 3.0]), np.array([np.inf, 0.0, np.inf])),
                               [1.0, 0.0, 3.0])
    x = np.random.default_rng(0).normal(size=30)
    assert np.array_equal(RM.taut_string(x, x), x)
    with pytest.raises(ValueError):
        RM.taut_string(np.array([1.0]), np.array([0.0]))
    with pytest.raises(ValueError):
        RM.floor_contact_tube(wobbly_motion(np.random.default_rng(0), 4), tolerance=-1.0)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 30))
def test_taut_string_is_least_total_variation(seed, F):
    """Against a linear program: min sum |x[t+1] - x[t]| subject to the bounds."""
    from scipy.optimize import linprog

    rng = np.random.default_rng(seed)
    s = np.cumsum(rng.normal(size=F))
    tol = rng.choice([0.0, 0.3, 1.0])
    on = rng.random(F) < 0.7
    lo, hi = np.where(on, s - tol, -np.inf), np.where(on, s + tol, np.inf)
    x = RM.taut_string(lo, hi)
    assert np.all(x[on] >= lo[on]) and np.all(x[on] <= hi[on])
    m = F - 1
    A = np.zeros((2 * m, F + m))
    for i in range(m):
        A[2 * i, [i, i + 1, F + i]] = [-1, 1, -1]
        A[2 * i + 1, [i, i + 1, F + i]] = [1, -1, -1]
    bounds = [(a if np.isfinite(a) else None, b if np.isfinite(b) else None) for a, b in zip(lo, hi)]
    res = linprog(np.r_[np.zeros(F), np.ones(m)], A_ub=A, b_ub=np.zeros(2 * m),
                  bounds=bounds + [(0, None)] * m)
    assert res.status == 0 and tv(x) <= res.fun + 1e-7


def test_content_floor_contact_tolerance():
    """tgst.api: tolerance 0 is today's per-frame contact; 0.9 cm keeps the lowest foot joint within 0.9 cm of
    the content's on the content's contact frames, moves the root less, and frees the flight frames."""
    from jaxgest.motion.synthetic import render_clip
    from jaxgest.tgst import api

    content = render_clip("greeting", "sad", seed=0)[0]
    F = content.num_frames
    t = np.arange(F)
    jump = np.where((t > 100) & (t < 160), 15 * np.sin(np.pi * (t - 100) / 60), 0)
    hips = K.forward_kinematics(content)[:, K._hips_index(content.skeleton)]
    content = RM.set_root_position(content, hips + jump[:, None] * np.array([0.0, 1.0, 0.0]))
    rng = np.random.default_rng(0)
    wobble = content.rotations.copy()
    legs = [content.skeleton.index(n) for n in content.skeleton.names if "Leg" in n or "Foot" in n]
    wobble[:, legs] = R.quat_normalize(R.quat_mul(wobble[:, legs], R.expmap_to_quat(
        rng.normal(scale=0.03, size=(F, len(legs), 3)))))
    result = content.replace(rotations=wobble)  # legs with frame-to-frame errors, the content's root
    feet = api.foot_names(content.skeleton)
    c_low = RM.lowest_foot_height(content, feet)
    contact = api.content_contact_frames(content)
    assert 0 < (~contact).sum() < F // 2
    today = api.content_floor_contact(result, content, tolerance=0.0)
    per_frame = RM.floor_contact(result, feet=feet, height=c_low)
    np.testing.assert_array_equal(today.translations, per_frame.translations)
    tube = api.content_floor_contact(result, content, tolerance=0.9)
    assert np.abs(RM.lowest_foot_height(tube, feet) - c_low)[contact].max() <= 0.9 + 1e-9
    h = K._hips_index(content.skeleton)
    y = {k: K.forward_kinematics(m)[:, h, 1] - hips[:, 1] - jump
         for k, m in (("today", today), ("tube", tube))}
    assert tv(y["tube"]) < tv(y["today"])

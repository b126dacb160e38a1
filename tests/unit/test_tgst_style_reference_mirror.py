"""The style reference (clip + its mirror, authors' protocol) on real Bandai-Namco clips: mirrored with the
rig's T-pose exactly as the training data (issue 36, defect a)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import SHARED
from jaxgest.motion import body, bvh, kinematics
from jaxgest.tgst import protocol
from jaxgest.tgst.data import mirror_motion

CLIPS = [SHARED / "data" / "bandai-namco-2" / "data" / "dataset-2_wave-left-hand_active_006.bvh",
         SHARED / "data" / "bandai-namco-1" / "data" / "dataset-1_walk-right_normal_001.bvh"]


def _max_arm_jump(motion) -> float:
    """Largest frame-to-frame displacement of an arm joint (root-local positions, cm)."""
    idx = body.joint_indices(motion.skeleton, body.ARMS)
    p = kinematics.root_local_positions(motion)[:, idx]
    return float(np.linalg.norm(np.diff(p, axis=0), axis=-1).max())


@pytest.mark.parametrize("path", CLIPS, ids=lambda p: p.name)
def test_style_reference_has_no_arm_jump_above_the_clips_own(path):
    if not path.is_file():
        pytest.skip(f"real data not found at {path}")
    clip = bvh.load(path)
    ref = protocol.style_reference(clip)
    own = _max_arm_jump(clip)
    assert _max_arm_jump(ref) <= own + 1e-6
    # the mirrored half is the training data's mirror (rig T-pose), frame for frame after the blend
    n = protocol.get_protocol("authors").transition_frames(clip.fps)
    np.testing.assert_allclose(ref.rotations[clip.num_frames:], mirror_motion(clip).rotations[n:])
    # and the test can fail: mirroring without the T-pose swings the arms through the body in the blend
    wrong = kinematics.append_motion(clip, kinematics.mirror(clip), n)
    assert _max_arm_jump(wrong) > 2 * own

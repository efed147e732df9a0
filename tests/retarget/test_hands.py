"""Finger closure rule: threshold on fingertip anchoring, rate-limited stroke."""

from __future__ import annotations

import numpy as np
import pytest

from robot_hoi.retarget.hands import GraspRule, HandJoints, closure_profile, finger_angles, holding


def test_holding_uses_the_mean_fingertip_anchor():
    anchor = np.array([[0.7, 0.2, 0.0], [0.6, 0.6, 1.0], [0.4, 0.5, 1.0]])
    np.testing.assert_array_equal(holding(anchor, [0, 1], 0.5), [False, True, False])
    assert not holding(anchor, [], 0.5).any()


def test_closure_ramps_at_the_configured_rate():
    rule = GraspRule(closure=0.6, ramp_s=0.3)
    hold = np.array([False] * 3 + [True] * 20 + [False] * 20)
    c = closure_profile(hold, fps=30.0, rule=rule)
    assert c[:3].tolist() == [0.0, 0.0, 0.0]
    step = 0.6 / 9.0  # full stroke in 0.3 s at 30 fps
    assert c[3] == pytest.approx(step)
    assert c[12] == pytest.approx(0.6) and c[22] == pytest.approx(0.6)
    assert np.abs(np.diff(c)).max() <= step + 1e-12
    assert c[-1] == 0.0


def test_finger_angles_interpolate_open_to_closed():
    hand = HandJoints("left", ("a", "b"), open_rad=(0.0, 0.6), closed_rad=(1.7, 1.3))
    np.testing.assert_allclose(finger_angles(hand, np.array([0.0, 0.5, 1.0])),
                               [[0.0, 0.6], [0.85, 0.95], [1.7, 1.3]])

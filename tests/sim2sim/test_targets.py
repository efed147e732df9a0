"""Evaluation targets: the policy's sidecar and a clip retargeted here describe the same reference; the object
and the per-frame hand-contact labels come from the clip; bad inputs are user errors."""

from __future__ import annotations

import numpy as np
import pytest

from robot_hoi.errors import UserError
from sim2sim.targets import clip_targets, policy_targets


def test_clip_retargeted_here_equals_the_exported_sidecar(contract, target):
    (again,) = clip_targets(contract, ["embedded:lift_place"], "g1_inspire", True)
    assert again.name == target.name
    for key in ("joint_pos", "root_pos", "root_quat_wxyz", "link_pos", "object_pos", "object_quat_wxyz"):
        np.testing.assert_allclose(getattr(again.motion, key), getattr(target.motion, key), atol=1e-5, err_msg=key)
    np.testing.assert_array_equal(again.hand_contact, target.hand_contact)
    assert target.hand_contact.shape == (target.motion.num_frames, 2) and target.hand_contact.any()
    assert target.object_points.shape == (256, 3)  # training's object_surface_points
    assert target.object_mass_kg == pytest.approx(2.0) and target.license  # the lift_place box


def test_missing_inputs_are_user_errors(contract, tmp_path):
    with pytest.raises(UserError, match="no such clip"):
        clip_targets(contract, [str(tmp_path / "nope.pt")], "g1_inspire", True)
    with pytest.raises(Exception, match="motion file not found"):
        policy_targets(contract, str(tmp_path / "nope.motion.npz"), "g1_inspire", True)

import numpy as np
import pytest

from robot_hoi.data.kinematics import bone_offsets, estimate_height_from_offsets
from robot_hoi.data.scale import (
    DEFAULT_ROBOT_HEIGHT_M,
    human_to_robot_scale,
    robot_height_from_embodiment,
    scale_clip,
    subject_height,
)
from robot_hoi.data.template_skeleton import TEMPLATE_HEIGHT_M, template_offsets
from robot_hoi.errors import UserError


def test_robot_height_comes_from_the_embodiment_yaml(tmp_path):
    assert robot_height_from_embodiment("g1_inspire") == pytest.approx(1.32)
    cfg = tmp_path / "bot.yaml"
    cfg.write_text("name: bot\nrobot_height: 1.55\n")
    assert robot_height_from_embodiment(cfg) == 1.55
    cfg.write_text("name: bot\n")
    assert robot_height_from_embodiment(cfg) == DEFAULT_ROBOT_HEIGHT_M
    cfg.write_text("robot_height: tall\n")
    with pytest.raises(UserError, match="robot_height"):
        robot_height_from_embodiment(cfg)
    with pytest.raises(UserError, match="not found"):
        robot_height_from_embodiment("no_such_robot")


def test_height_table_and_skeleton_estimate(lift_clip):
    assert subject_height("sub3", lift_clip.body_pos, lift_clip.body_quat_xyzw).height_m == 1.941
    est = subject_height("sub99", lift_clip.body_pos, lift_clip.body_quat_xyzw)
    assert est.source == "estimated" and est.height_m == pytest.approx(TEMPLATE_HEIGHT_M, rel=0.02)
    assert estimate_height_from_offsets(template_offsets()) == pytest.approx(TEMPLATE_HEIGHT_M, rel=0.02)


def test_scale_factor_and_scaled_clip(lift_clip):
    factor = human_to_robot_scale(lift_clip, 1.32)
    assert factor == pytest.approx(1.32 / 1.75)
    unknown = lift_clip.copy()
    unknown.subject_height_m, unknown.subject = None, None
    assert human_to_robot_scale(unknown) == pytest.approx(1.32 / 1.75, rel=0.02)
    small = scale_clip(lift_clip, factor)
    np.testing.assert_allclose(small.body_pos, lift_clip.body_pos * factor)
    np.testing.assert_allclose(small.object.vertices, lift_clip.object.vertices * factor)
    np.testing.assert_array_equal(small.body_quat_xyzw, lift_clip.body_quat_xyzw)
    offsets = np.median(bone_offsets(small.body_pos, small.body_quat_xyzw), axis=0)
    np.testing.assert_allclose(offsets, template_offsets() * factor, atol=1e-9)
    assert small.subject_height_m == pytest.approx(1.32)
    human_only = scale_clip(lift_clip, factor, scale_object=False)
    np.testing.assert_array_equal(human_only.object_pos, lift_clip.object_pos)
    with pytest.raises(UserError):
        scale_clip(lift_clip, 0.0)

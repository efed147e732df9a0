import numpy as np
import pytest

from robot_hoi.embodiment.clip_view import heading, render_view, robot_points, robot_skeleton

mujoco = pytest.importorskip("mujoco")


@pytest.fixture(scope="module")
def skeleton():
    return robot_skeleton("g1_inspire")


def test_robot_skeleton_is_the_standing_g1(skeleton):
    z = skeleton.points[1:, 2]
    assert 1.0 < z.max() < 1.45 and z.min() < 0.1  # head-ish height of a 1.32 m robot, feet near the floor
    assert len(skeleton.edges) > 20 and skeleton.height_m == pytest.approx(1.32)


def test_robot_stands_beside_the_human_and_follows_heading(skeleton, lift_clip):
    frame = 40
    yaw = heading(lift_clip.body_quat_xyzw[frame : frame + 1])[0]
    points = robot_points(skeleton, lift_clip, frame, side_offset=1.0)
    root = points[1]  # the robot's base body
    right = np.array([np.sin(yaw), -np.cos(yaw)])  # the human's right on the floor
    offset = root[:2] - lift_clip.root_pos[frame, :2]
    assert (
        offset @ right == pytest.approx(1.0, abs=0.05)
        and abs(offset @ np.array([np.cos(yaw), np.sin(yaw)])) < 0.05
    )
    # robot points are a rigid yaw of the default pose: heights unchanged
    np.testing.assert_allclose(np.sort(points[:, 2]), np.sort(skeleton.points[:, 2]), atol=1e-9)


def test_short_mp4(lift_clip, tmp_path):
    out = render_view(lift_clip.select_frames(slice(60, 72)), tmp_path / "clip.mp4", embodiment="g1_inspire")
    import imageio.v2 as imageio

    frames = [
        frame for frame in imageio.get_reader(out)
    ]  # (list() would ask the reader for an infinite length)
    assert len(frames) == 6 and frames[0].shape[2] == 3 and frames[0].std() > 5

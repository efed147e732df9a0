"""The human -> robot target mapping against hand-computed values."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robot_hoi.errors import DataError
from robot_hoi.retarget.targets import (
    TargetMapping,
    anchor_weights,
    fit_hand_size,
    link_group,
    map_positions,
    surface_distance,
    targets_from_clip,
    wxyz_to_xyzw,
    xyzw_to_wxyz,
)

# A 1 m cube's face centres and corners as "sample points" (object frame).
CUBE_POINTS = np.array(
    [[0.5, 0, 0], [-0.5, 0, 0], [0, 0.5, 0], [0, -0.5, 0], [0, 0, 0.5], [0, 0, -0.5]]
    + [[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)],
    dtype=np.float64,
)


def _scene():
    """Two frames. Object (cube) rests at z 0.5 (frame 0) then is lifted 1 m and yawed 90 deg (frame 1).
    Links: 0 = far away, 1 = on the cube's +x face in frame 1 (in frame 0 it is 2 m away), 2 = 7.5 cm off the face."""
    s = 0.5
    obj_pos = np.array([[5.0, 5.0, 0.5], [5.0, 6.0, 1.5]])
    yaw = Rotation.from_euler("z", [[0.0], [90.0]], degrees=True)
    obj_quat = yaw.as_quat()
    touching = obj_pos[1] + yaw[1].apply([0.5, 0.0, 0.0])  # the +x face centre, in world
    human = np.array([
        [[1.4, 2.2, 1.0], touching - [0.0, 2.0, 0.0], [9.0, 9.0, 0.0]],
        [[1.4, 2.2, 1.0], touching, touching + yaw[1].apply([0.075, 0.0, 0.0])],
    ])  # fmt: skip
    root_xy = np.array([[1.0, 2.0], [1.0, 2.0]])
    return s, obj_pos, obj_quat, human, root_xy


def test_body_scaling_object_height_and_anchoring_by_hand():
    s, obj_pos, obj_quat, human, root_xy = _scene()
    targets, a, obj_robot, dist = map_positions(human, root_xy, obj_pos, obj_quat, CUBE_POINTS, s, TargetMapping())
    # far link: p' = [root'_xy + s (p_xy - root_xy), s z] (the root does not move here: root' = root)
    np.testing.assert_allclose(targets[:, 0], [[1.2, 2.1, 0.5], [1.2, 2.1, 0.5]])
    np.testing.assert_allclose(a[:, 0], 0.0)
    # object: height above rest (0.5) scaled: 0.5 + 0.5 * 1.0; horizontally the pelvis-to-surface gap is scaled.
    # Frame 0: offset (4, 3), |.| = 5, dir (0.8, 0.6), the cube's extent toward the pelvis r = 0.5 (0.8 + 0.6) = 0.7
    # (a corner): o' = (1, 2) + dir (0.5 (5 - 0.7) + 0.7) = (3.28, 3.71). Frame 1: offset (4, 4), r = 0.5 sqrt(2):
    # o' = (1, 2) + (1, 1) / sqrt(2) * (0.5 (4 sqrt(2) - r) + r) = (3.25, 4.25).
    np.testing.assert_allclose(obj_robot, [[3.28, 3.71, 0.5], [3.25, 4.25, 1.0]], atol=1e-9)
    # touching link: a = 1, follows the object: same object-frame point, robot-space pose
    assert dist[1, 1] == pytest.approx(0.0, abs=1e-12)
    assert a[1, 1] == pytest.approx(1.0)
    np.testing.assert_allclose(targets[1, 1], obj_robot[1] + Rotation.from_quat(obj_quat[1]).apply([0.5, 0, 0]))
    robot_dist = surface_distance(targets[:, 1:2], obj_robot, obj_quat, CUBE_POINTS)
    assert robot_dist[1, 0] == pytest.approx(0.0, abs=1e-12)  # still on the surface of the real-size cube
    # 7.5 cm off the face: a = 1 - 0.075 / 0.15 = 0.5, target halfway between anchored and scaled
    assert a[1, 2] == pytest.approx(0.5)
    p = human[1, 2]
    scaled = np.array([1.0 + s * (p[0] - 1.0), 2.0 + s * (p[1] - 2.0), s * p[2]])
    anchored = p + (obj_robot[1] - obj_pos[1])
    np.testing.assert_allclose(targets[1, 2], 0.5 * anchored + 0.5 * scaled)


def test_object_height_kept_when_switched_off():
    s, obj_pos, obj_quat, human, root_xy = _scene()
    mapping = TargetMapping(scale_object_height=False)
    _, _, obj_robot, _ = map_positions(human, root_xy, obj_pos, obj_quat, CUBE_POINTS, s, mapping)
    np.testing.assert_allclose(obj_robot[:, 2], obj_pos[:, 2])


def test_contact_labels_override_distance_weights():
    dist = np.array([[0.0, 0.03, 0.3]])
    np.testing.assert_allclose(anchor_weights(dist, 0.15), [[1.0, 0.8, 0.0]])
    labels = np.array([[-1, 0, 1]])
    np.testing.assert_allclose(anchor_weights(dist, 0.15, labels), [[0.0, 0.8, 1.0]])


def test_dense_local_distance_is_used_when_given():
    s, obj_pos, obj_quat, human, root_xy = _scene()
    calls = []

    def local_distance(points_local):
        calls.append(points_local.shape)
        return np.zeros(points_local.shape[:-1])

    _, a, _, _ = map_positions(human, root_xy, obj_pos, obj_quat, CUBE_POINTS, s, TargetMapping(),
                               local_distance=local_distance)
    assert calls == [(2, 3, 3)]
    np.testing.assert_allclose(a, 1.0)


def test_link_groups_and_quaternion_order():
    assert [link_group(n) for n in ("Pelvis", "L_Knee", "R_Toe", "Head", "L_Elbow", "R_Wrist", "L_Thumb3")] == [
        "pelvis", "legs", "feet", "head", "arms", "wrists", "fingers"]
    with pytest.raises(DataError):
        link_group("Tail")
    q = np.array([0.1, 0.2, 0.3, 0.9])
    np.testing.assert_allclose(xyzw_to_wxyz(q), [0.9, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(wxyz_to_xyzw(xyzw_to_wxyz(q)), q)


def _fake_clip(T=3):
    from robot_hoi.data.layout import BODY_INDEX

    body_pos = np.zeros((T, 52, 3))
    body_pos[:, :, 2] = 1.0
    body_pos[:, BODY_INDEX["L_Wrist"]] = [0.5, 0.0, 1.0]
    body_quat = np.tile([0.0, 0.0, 0.0, 1.0], (T, 52, 1))
    return SimpleNamespace(
        name="fake", fps=30.0, body_pos=body_pos, body_quat_xyzw=body_quat,
        object_pos=np.tile([3.0, 0.0, 0.5], (T, 1)), object_quat_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (T, 1)),
        body_contact=np.zeros((T, 52), dtype=np.int8), subject_height_m=2.0,
        object=SimpleNamespace(sample_points=CUBE_POINTS, mass_kg=None),
    )  # fmt: skip


def test_targets_from_clip_uses_the_link_map_and_height_ratio():
    cfg = SimpleNamespace(robot_height=1.3, link_map={"pelvis": "Pelvis", "left_wrist_yaw_link": "L_Wrist"})
    t = targets_from_clip(_fake_clip(), cfg)
    assert t.scale == pytest.approx(0.65)
    assert t.link_names == ("pelvis", "left_wrist_yaw_link") and t.human_names == ("Pelvis", "L_Wrist")
    np.testing.assert_allclose(t.pos[0, 1], [0.65 * 0.5, 0.0, 0.65])
    np.testing.assert_allclose(t.object_quat_wxyz[0], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(t.root_quat_wxyz[0], [1.0, 0.0, 0.0, 0.0])
    assert t.weight.shape == (3, 2) and np.all(t.weight > 0)
    assert targets_from_clip(_fake_clip(), cfg, scale=0.5).scale == 0.5


def test_targets_from_clip_rejects_bad_inputs():
    cfg = SimpleNamespace(robot_height=1.3, link_map={"pelvis": "Pelvis", "x": "NoSuchBody"})
    with pytest.raises(DataError, match="NoSuchBody"):
        targets_from_clip(_fake_clip(), cfg)
    cfg = SimpleNamespace(robot_height=1.3, link_map={"pelvis": "Pelvis"})
    clip = _fake_clip()
    clip.object = None
    with pytest.raises(DataError, match="no object"):
        targets_from_clip(clip, cfg)
    with pytest.raises(DataError, match="anchor_mode"):
        TargetMapping(anchor_mode="nearest")


def test_hand_size_fit_scales_each_hand_about_its_palm():
    """The robot hand twice the human's: wrist and fingertip targets move away from the palm centre (wrist to middle
    knuckle midpoint) by 2x; the palm centre, other links and the other hand's links (no length given) stay."""
    from robot_hoi.data.layout import BODY_INDEX, BODY_NAMES

    body = np.random.default_rng(0).normal(size=(2, len(BODY_NAMES), 3))
    names = ["Pelvis", "L_Wrist", "L_Index3", "L_Thumb3", "R_Wrist", "R_Index3"]
    human = body[:, [BODY_INDEX[n] for n in names]]
    wrist, knuckle = body[:, BODY_INDEX["L_Wrist"]], body[:, BODY_INDEX["L_Middle1"]]
    tips = human[:, 2:4]
    length = 2.0 * float(np.linalg.norm(tips - wrist[:, None], axis=-1).mean())
    out = fit_hand_size(body, human, names, {"left": length})
    palm = 0.5 * (wrist + knuckle)
    np.testing.assert_allclose(out[:, 1:4], palm[:, None] + 2.0 * (human[:, 1:4] - palm[:, None]))
    np.testing.assert_array_equal(out[:, [0, 4, 5]], human[:, [0, 4, 5]])

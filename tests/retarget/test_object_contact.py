"""Hands vs the object's convex hull: distances, push-out of targets, probe points, and the IK keeping out."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import trimesh

from robot_hoi.retarget.ik import IKSolver
from robot_hoi.retarget.object_contact import HullPlanes, hand_probe_points
from robot_hoi.retarget.targets import TargetMapping, map_positions

CUBE = HullPlanes.from_vertices(trimesh.creation.box(extents=(1.0, 1.0, 1.0)).vertices)
_GRID = np.array([[u, v] for u in np.linspace(-0.5, 0.5, 11) for v in np.linspace(-0.5, 0.5, 11)])
CUBE_SAMPLES = np.concatenate([np.insert(_GRID, axis, side, axis=1) for axis in range(3) for side in (-0.5, 0.5)])


def test_signed_distance_and_push_out_on_a_cube():
    pts = np.array([[0.0, 0.0, 0.0], [0.45, 0.0, 0.0], [0.0, 0.0, 0.8], [0.0, -0.52, 0.1]])
    dist, face = CUBE.signed_distance(pts)
    np.testing.assert_allclose(dist, [-0.5, -0.05, 0.3, 0.02], atol=1e-12)
    np.testing.assert_allclose(CUBE.normals[face[1]], [1.0, 0.0, 0.0], atol=1e-12)
    out = CUBE.push_out(pts, clearance=0.01)
    np.testing.assert_allclose(out[1], [0.51, 0.0, 0.0], atol=1e-12)  # out through the nearest face
    np.testing.assert_allclose(out[2:], pts[2:])  # already clear: untouched
    assert np.all(CUBE.signed_distance(out)[0] >= 0.01 - 1e-12)


def test_anchored_targets_inside_the_object_are_pushed_to_its_surface():
    # A cube resting at the origin (no lift), a hand joint 3 cm inside its +x face: anchored and moved out.
    T = 1
    human = np.array([[[0.47, 0.0, 0.5], [3.0, 0.0, 1.0]]])
    obj_pos, obj_quat = np.array([[0.0, 0.0, 0.5]]), np.array([[0.0, 0.0, 0.0, 1.0]])
    pts = CUBE_SAMPLES
    targets, a, _, _ = map_positions(human, np.zeros((T, 2)), obj_pos, obj_quat, pts, 0.5, TargetMapping(),
                                     hull=CUBE)
    assert a[0, 0] == pytest.approx(0.8)  # 3 cm from the nearest surface sample
    scaled = np.array([0.5 * 0.47, 0.0, 0.5 * 0.5])
    pushed = np.array([0.51, 0.0, 0.5])  # out through the +x face to the 1 cm clearance
    np.testing.assert_allclose(targets[0, 0], 0.8 * pushed + 0.2 * scaled, atol=1e-9)
    off, _, _, _ = map_positions(human, np.zeros((T, 2)), obj_pos, obj_quat, pts, 0.5,
                                 TargetMapping(object_clearance=None), hull=CUBE)
    np.testing.assert_allclose(off[0, 0], 0.8 * human[0, 0] + 0.2 * scaled, atol=1e-9)


# A table in its own frame (z up): a 0.6 x 0.6 x 0.06 m top at 0.6-0.66 m on one 8 cm leg, as two convex pieces
TABLE = HullPlanes.from_pieces([
    np.array([[x, y, z] for x in (-0.3, 0.3) for y in (-0.3, 0.3) for z in (0.6, 0.66)]),
    np.array([[x, y, z] for x in (0.22, 0.3) for y in (0.22, 0.3) for z in (0.0, 0.6)]),
])


def test_signed_distance_is_the_nearest_piece_of_each_pieces_nearest_face():
    """The vectorised distance equals its definition, piece by piece, for any leading shape (ties: first piece)."""
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.5, 0.8, size=(4, 25, 3))
    values = pts @ TABLE.normals.T + TABLE.offsets
    top, leg = values[..., :TABLE.piece_starts[1]], values[..., TABLE.piece_starts[1]:]
    expected = np.minimum(top.max(-1), leg.max(-1))
    expected_face = np.where(leg.max(-1) < top.max(-1), leg.argmax(-1) + TABLE.piece_starts[1], top.argmax(-1))
    dist, face = TABLE.signed_distance(pts)
    np.testing.assert_allclose(dist, expected, atol=1e-12)
    np.testing.assert_array_equal(face, expected_face)
    one, one_face = TABLE.signed_distance(pts[1, 2])
    assert one.shape == () and one == pytest.approx(dist[1, 2]) and int(one_face) == face[1, 2]


def test_the_broad_phase_is_exact_within_its_range_and_a_lower_bound_beyond():
    rng = np.random.default_rng(1)
    pieces = [rng.normal(size=(40, 3)) * 0.1 + centre for centre in ((0, 0, 0), (0.3, 0, 0), (0, 0.4, 0.2))]
    planes = HullPlanes.from_pieces(pieces)
    pts = rng.uniform(-0.6, 0.8, size=(400, 3))
    exact, exact_face = planes.signed_distance(pts)
    for within in (0.0, 0.05, 0.2):
        dist, face = planes.signed_distance(pts, within)
        near = exact < within
        assert 0 < near.sum() < len(pts)
        np.testing.assert_array_equal(dist[near], exact[near])
        np.testing.assert_array_equal(face[near], exact_face[near])
        assert (dist[~near] >= within).all() and (dist[~near] <= exact[~near] + 1e-12).all()
    one, _ = planes.signed_distance(pts[0], 0.05)
    assert one.shape == ()


# A fixed-base arm whose "hand" carries a capsule finger; the object is a 1 m cube centred at (0.9, 0, 0.5).
ARM = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="base" pos="0 0 0.5">
      <joint name="yaw" axis="0 0 1" range="-3 3"/>
      <joint name="pitch" axis="0 1 0" range="-1.5 1.5"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" contype="0" conaffinity="0"/>
      <body name="wrist" pos="0.3 0 0">
        <joint name="slide" type="slide" axis="1 0 0" range="-0.2 0.2"/>
        <geom name="finger" type="capsule" fromto="0 0 0 0.1 0 0" size="0.01"/>
        <site name="tip" pos="0.1 0 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_probe_points_follow_the_collision_geoms():
    model = mujoco.MjModel.from_xml_string(ARM)
    wrist = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "wrist")
    probes = hand_probe_points(model, [wrist])
    assert len(probes) == 2  # the finger capsule's two end centres; the non-colliding arm capsule is skipped
    np.testing.assert_allclose(sorted(probes.local[:, 0]), [0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(probes.radius, 0.01)


def test_ik_keeps_the_hand_out_of_the_object():
    model = mujoco.MjModel.from_xml_string(ARM)
    wrist = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "wrist")
    solver = IKSolver(model, ["tip"], ["yaw", "pitch", "slide"], probes=hand_probe_points(model, [wrist]))
    T = 3
    target = np.tile([[[0.6, 0.0, 0.5]]], (T, 1, 1))  # 20 cm inside the cube's -x face (at x = 0.4)
    track = (CUBE, np.tile([0.9, 0.0, 0.5], (T, 1)), np.tile([1.0, 0.0, 0.0, 0.0], (T, 1)))
    free = solver.solve(target, np.ones((T, 1)), object_track=track)
    # The fingertip probe (radius 1 cm) stops at the face, give or take the soft constraint's 1 cm of give
    # (link weight 1 x 20 cm of error against object weight 20).
    assert free.object_penetration.max() < 0.015
    assert free.link_pos[-1, 0, 0] < 0.405
    ignored = solver.solve(target, np.ones((T, 1)))  # without the object the tip goes in
    assert ignored.link_pos[-1, 0, 0] > 0.55


def test_ik_keeps_the_hand_above_the_floor():
    """A fingertip target below the floor (OMOMO hands grip a floor box under its bottom edge): the finger's probe
    spheres stay `hand_floor_clearance` above it; with the floor rows off the tip goes under."""
    from dataclasses import replace

    from robot_hoi.retarget.ik import IKSettings

    model = mujoco.MjModel.from_xml_string(ARM)
    wrist = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "wrist")
    probes = hand_probe_points(model, [wrist])
    T = 3
    target = np.tile([[[0.2, 0.0, -0.05]]], (T, 1, 1))  # 5 cm below the floor, reachable by pitching down
    kept = IKSolver(model, ["tip"], ["yaw", "pitch", "slide"], probes=probes).solve(target, np.ones((T, 1)))
    # the tip probe (radius 1 cm) ends at 1 cm clearance, give or take the soft rows' give (weight 50 vs 1)
    assert kept.link_pos[-1, 0, 2] > 0.01 + 0.01 - 0.005
    assert kept.hand_floor_depth.max() < 0.005
    off = replace(IKSettings(), hand_floor_clearance=-1.0)
    under = IKSolver(model, ["tip"], ["yaw", "pitch", "slide"], probes=probes, settings=off).solve(
        target, np.ones((T, 1)))
    assert under.link_pos[-1, 0, 2] < -0.045 and under.hand_floor_depth.max() > 0.05


def test_ik_keeps_the_arm_out_of_the_object():
    """The upper arm's collision geometry is probed too (`arm_roots`): OMOMO's sub3_largebox_003 had the left elbow
    3 cm inside the box, which in simulation pushed the box away from the other hand. A 10 cm cube around the arm's
    end, the fingertip target beyond it: with the hand's probes alone the arm goes through the cube."""
    model = mujoco.MjModel.from_xml_string(ARM.replace('contype="0" conaffinity="0"', ""))  # the arm collides
    base, wrist = (mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) for n in ("base", "wrist"))
    with_arm = hand_probe_points(model, [wrist], [base])
    assert len(with_arm) == 4 and with_arm.hand.tolist() == [True, True, False, False]
    assert hand_probe_points(model, [wrist]).hand.all()
    cube = HullPlanes.from_vertices(trimesh.creation.box(extents=(0.1, 0.1, 0.1)).vertices)
    T = 3
    track = (cube, np.tile([0.3, 0.0, 0.5], (T, 1)), np.tile([1.0, 0.0, 0.0, 0.0], (T, 1)))
    target = np.tile([[[0.6, 0.0, 0.5]]], (T, 1, 1))  # straight ahead: the arm's end (x 0.3) sits in the cube

    def arm_depth(probes):
        result = IKSolver(model, ["tip"], ["yaw", "pitch", "slide"], probes=probes).solve(
            target, np.ones((T, 1)), object_track=track)
        data = mujoco.MjData(model)
        data.qpos[:] = result.qpos[-1]
        mujoco.mj_kinematics(model, data)
        end = data.xpos[base] + data.xmat[base].reshape(3, 3) @ np.array([0.3, 0.0, 0.0])
        return 0.02 - cube.signed_distance((end - [0.3, 0.0, 0.5])[None])[0][0], result

    inside, _ = arm_depth(hand_probe_points(model, [wrist]))
    assert inside > 0.06  # the capsule end 5 cm deep plus its 2 cm radius
    kept, result = arm_depth(with_arm)
    assert kept < 0.015 and result.object_penetration.max() < 0.015


def test_the_g1_arm_probes_start_at_the_upper_arm():
    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.retarget.pipeline import RetargetOptions, _ancestors

    model = build_model(load_embodiment("g1_inspire"))
    wrists = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{s}_wrist_yaw_link") for s in ("left", "right")]
    roots = _ancestors(model, np.array(wrists), RetargetOptions().arm_probe_levels)
    assert [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in roots] == [
        "left_shoulder_yaw_link", "right_shoulder_yaw_link"]
    probes = hand_probe_points(model, wrists, roots)
    assert 0 < (~probes.hand).sum() < len(probes)  # upper arm, elbow and wrist links probed besides the hands

"""The IK core on tiny inline models: reaches reachable targets, respects limits, keeps feet above the floor."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from robot_hoi.errors import UserError
from robot_hoi.retarget.ik import IKSolver, sole_points
from robot_hoi.retarget.kinematics import apply_joint_couplings, link_positions, resolve_links

ARM = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="base">
      <joint name="j0" axis="0 0 1" range="-2 2"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.03"/>
      <body name="upper" pos="0 0 0.3">
        <joint name="j1" axis="0 1 0" range="-1.5 1.5"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
        <body name="fore" pos="0.3 0 0">
          <joint name="j2" axis="0 1 0" range="-2.5 0.2"/>
          <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.03"/>
          <body name="hand" pos="0.25 0 0">
            <joint name="j3" axis="1 0 0" range="-1 1"/>
            <geom type="box" size="0.02 0.05 0.01"/>
            <site name="tip" pos="0.05 0.04 0"/>
            <body name="finger" pos="0.05 0 0">
              <joint name="f0" axis="0 1 0" range="0 1.5"/>
              <geom type="capsule" fromto="0 0 0 0.04 0 0" size="0.008"/>
              <body name="finger2" pos="0.04 0 0">
                <joint name="f1" axis="0 1 0" range="0 3"/>
                <geom type="capsule" fromto="0 0 0 0.03 0 0" size="0.008"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <equality><joint joint1="f1" joint2="f0" polycoef="0 2 0 0 0"/></equality>
</mujoco>
"""

# A floating two-link "leg" with a box foot: free base + hip + knee.
LEG = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="hip_body" pos="0 0 0.6">
      <freejoint name="root"/>
      <geom type="sphere" size="0.05"/>
      <body name="thigh">
        <joint name="hip" axis="0 1 0" range="-2 2"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.03"/>
        <body name="shin" pos="0 0 -0.3">
          <joint name="knee" axis="0 1 0" range="0 2.5"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.25" size="0.03"/>
          <body name="foot" pos="0 0 -0.27">
            <joint name="ankle" axis="0 1 0" range="-0.8 0.8"/>
            <geom name="sole" type="box" size="0.08 0.04 0.02" pos="0.03 0 0"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

ARM_JOINTS = ["j0", "j1", "j2", "j3"]


def _fk(model, qpos, names):
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return link_positions(data, resolve_links(model, names))


def test_reaches_reachable_targets_to_sub_millimetre():
    model = mujoco.MjModel.from_xml_string(ARM)
    links = ["fore", "hand", "tip"]
    solver = IKSolver(model, links, ARM_JOINTS)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(20):
        q_true = np.zeros(model.nq)
        q_true[:4] = rng.uniform(model.jnt_range[:4, 0] * 0.9, model.jnt_range[:4, 1] * 0.9)
        targets = _fk(model, q_true, links)
        start = q_true.copy()
        start[:4] += rng.uniform(-0.4, 0.4, 4)  # warm start, as from the previous frame
        q, _ = solver.solve_frame(start, targets, np.ones(3), 100)
        worst = max(worst, np.linalg.norm(_fk(model, q, links) - targets, axis=1).max())
    assert worst < 1e-3


def test_follows_a_reachable_trajectory():
    model = mujoco.MjModel.from_xml_string(ARM)
    links = ["hand", "tip"]
    solver = IKSolver(model, links, ARM_JOINTS)
    t = np.linspace(0.0, 1.0, 30)
    q_path = np.zeros((30, model.nq))
    q_path[:, :4] = np.stack([1.2 * t - 0.6, 0.5 * np.sin(3 * t), -1.0 + 0.5 * t, 0.3 * np.cos(2 * t)], axis=1)
    targets = np.stack([_fk(model, q, links) for q in q_path])
    result = solver.solve(targets, np.ones((30, 2)), qpos_init=q_path[0] + 0.2)
    assert result.residual.max() < 1e-3


def test_joint_limits_hold_for_unreachable_targets():
    model = mujoco.MjModel.from_xml_string(ARM)
    solver = IKSolver(model, ["tip"], ARM_JOINTS)
    # Straight behind the base needs the base yaw j0 at pi, beyond its +-2 rad; j1 cannot swing over the top.
    result = solver.solve(np.array([[[-0.5, 0.0, 0.3]]]), np.ones((1, 1)), qpos_init=np.array([1.5, 0, -0.5, 0, 0, 0]))
    q = result.qpos[0]
    lo, hi = model.jnt_range[:4, 0], model.jnt_range[:4, 1]
    assert np.all(q[:4] >= lo - 1e-9) and np.all(q[:4] <= hi + 1e-9)
    assert result.at_limit[0, 0], "the base yaw presses against its limit"
    assert q[0] == pytest.approx(2.0)
    assert result.residual[0, 0] > 0.1


def test_untouched_joints_come_from_the_preset_and_couplings_follow():
    model = mujoco.MjModel.from_xml_string(ARM)
    solver = IKSolver(model, ["tip"], ARM_JOINTS)
    targets = np.tile(_fk(model, np.zeros(model.nq), ["tip"]), (2, 1, 1)) + [0.0, 0.05, 0.0]
    preset = np.zeros((2, model.nq))
    preset[:, 4] = [0.3, 1.2]  # finger driver f0 per frame
    result = solver.solve(targets, np.ones((2, 1)), preset_qpos=preset)
    np.testing.assert_allclose(result.qpos[:, 4], [0.3, 1.2])
    np.testing.assert_allclose(result.qpos[:, 5], [0.6, 2.4])  # f1 = 2 * f0 (joint equality)


def test_apply_joint_couplings_uses_the_polynomial():
    model = mujoco.MjModel.from_xml_string(ARM)
    q = np.zeros(model.nq)
    q[4] = 0.7
    apply_joint_couplings(model, q)
    assert q[5] == pytest.approx(1.4)


def test_floor_keeps_the_foot_above_ground_and_base_moves():
    model = mujoco.MjModel.from_xml_string(LEG)
    links = ["hip_body", "foot"]
    default = model.qpos0.copy()
    default[7:10] = [-0.3, 0.6, -0.3]  # knee bent, as a humanoid's default stand (a straight knee is singular)
    solver = IKSolver(model, links, ["hip", "knee", "ankle"], default, foot_link_names=["foot"])
    assert len(solver.sole_body) >= 4  # the box's lowest corners
    # Ask for the foot 10 cm below the floor and the hip low: the sole must stay on or above z = 0.
    T = 5
    targets = np.zeros((T, 2, 3))
    targets[:, 0] = [0.1, 0.0, 0.45]
    targets[:, 1] = [0.1, 0.0, -0.10]
    result = solver.solve(targets, np.ones((T, 2)))
    assert result.sole_min_z.min() >= -1e-6
    # The foot target was raised to its flat-foot height (its origin 2 cm above the sole), so it is reachable.
    assert result.residual[:, 1].max() < 0.01
    assert result.residual[:, 0].max() < 0.01


def test_sole_points_are_the_lowest_box_corners():
    model = mujoco.MjModel.from_xml_string(LEG)
    foot = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "foot")
    bodies, local = sole_points(model, model.qpos0, [foot])
    assert np.all(bodies == foot)
    np.testing.assert_allclose(np.sort(local[:, 0]), [-0.05, -0.05, 0.11, 0.11])
    np.testing.assert_allclose(local[:, 2], -0.02)


def test_landmark_offsets_move_the_ik_point():
    model = mujoco.MjModel.from_xml_string(ARM)
    solver = IKSolver(model, ["hand"], ARM_JOINTS, landmarks={"hand": ("hand", (0.1, 0.0, 0.0))})
    target = _fk(model, np.zeros(model.nq), ["hand"]) + [0.1, 0.0, 0.0]  # the landmark of the zero pose
    result = solver.solve(target[None], np.ones((1, 1)), qpos_init=np.zeros(model.nq))
    assert result.residual[0, 0] < 1e-3
    np.testing.assert_allclose(result.link_pos[0, 0], target[0] - [0.1, 0.0, 0.0], atol=2e-3)


def test_unknown_link_name_is_a_user_error():
    model = mujoco.MjModel.from_xml_string(ARM)
    with pytest.raises(UserError, match="nope"):
        IKSolver(model, ["hand", "nope"])

"""Observation terms against values worked out by hand (pelvis yawed 90 deg, so H^T (x, y, z) = (y, -x, z))."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.devpolicy import make_contract
from deploy.embodiment import load_embodiment
from deploy.errors import DeployError
from deploy.motion import ReferenceMotion
from deploy.observations import TERM_FUNCTIONS, ObservationBuilder, RobotState

from .conftest import EMBODIMENT_YAML

C45 = np.sqrt(0.5)
YAW90 = np.array([C45, 0, 0, C45])
YAW180 = np.array([0.0, 0, 0, 1])
PELVIS = np.array([1.0, 2.0, 0.8])


@pytest.fixture(scope="module")
def contract():
    return make_contract(load_embodiment(EMBODIMENT_YAML), keyframes=(1, 16))


@pytest.fixture(scope="module")
def motion(contract):
    num_links = len(contract.link_names)
    offsets = np.stack([np.arange(num_links) * 0.01, np.zeros(num_links), np.zeros(num_links)], axis=1)
    root = np.stack([PELVIS, PELVIS + [1, 0, 0], PELVIS + [0, 0, 0.1]])
    return ReferenceMotion(
        fps=30.0,
        joint_pos=np.stack([contract.default_pose, contract.default_pose + 0.2, contract.default_pose - 0.1]),
        root_pos=root,
        root_quat_wxyz=np.stack([YAW90, YAW90, YAW180]),
        link_pos=root[:, None, :] + offsets[None],
        object_pos=np.stack([PELVIS, PELVIS + [0, 2, 0], PELVIS + [0, 0, -0.3]]),
        object_quat_wxyz=np.stack([YAW90, YAW180, YAW90]),
    )


@pytest.fixture
def state(contract):
    return RobotState(
        joint_pos=contract.default_pose[:29] + 0.1,
        joint_vel=np.arange(29) * 0.01,
        imu_quat_wxyz=np.array([C45, C45, 0, 0]),  # rolled +90 deg about x
        gyro=np.array([0.1, -0.2, 0.3]),
        hand_angles=np.array([1000] * 6 + [0] * 6),  # left open, right closed
        hand_forces=np.array([1000] * 6 + [-500] * 6),
        pelvis_pos=PELVIS.copy(),
        pelvis_quat_wxyz=YAW90.copy(),
        object_pos=PELVIS + [0.0, 1.0, 0.2],
        object_quat_wxyz=YAW180.copy(),
        last_action=np.linspace(-1, 1, 41),
        tick=0,
    )


def term(name, state, contract, motion):
    builder = ObservationBuilder(contract, motion)
    return TERM_FUNCTIONS[name](state, builder.ctx)


def test_projected_gravity_and_gyro(state, contract, motion):
    np.testing.assert_allclose(term("projected_gravity", state, contract, motion), [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(term("base_ang_vel", state, contract, motion), [0.1, -0.2, 0.3])
    state.imu_quat_wxyz = np.array([1.0, 0, 0, 0])
    np.testing.assert_allclose(term("projected_gravity", state, contract, motion), [0, 0, -1], atol=1e-12)


def test_joint_pos_converts_hand_units_to_radians(state, contract, motion):
    value = term("joint_pos", state, contract, motion)
    np.testing.assert_allclose(value[:29], 0.1)
    # left open: fingers/thumb bend at open 0.0 (default 0), thumb rotate at open -0.1 (default 0.6)
    np.testing.assert_allclose(value[29:35], [0, 0, 0, 0, 0, -0.7], atol=1e-12)
    # right closed: fingers 1.7, thumb bend 0.5, thumb rotate 1.3 - 0.6
    np.testing.assert_allclose(value[35:41], [1.7, 1.7, 1.7, 1.7, 0.5, 0.7], atol=1e-12)


def test_joint_vel_hand_force_last_action(state, contract, motion):
    np.testing.assert_allclose(term("joint_vel", state, contract, motion), np.arange(29) * 0.01)
    np.testing.assert_allclose(term("hand_force", state, contract, motion), [0.981] * 6 + [-0.4905] * 6)
    np.testing.assert_allclose(term("last_action", state, contract, motion), np.linspace(-1, 1, 41))


def test_object_terms_in_heading_frame(state, contract, motion):
    np.testing.assert_allclose(term("object_pos", state, contract, motion), [1.0, 0.0, 0.2], atol=1e-12)
    # object yaw 180 seen from heading 90: Rz(90) -> columns (0, 1, 0) and (-1, 0, 0)
    np.testing.assert_allclose(term("object_rot", state, contract, motion), [0, 1, 0, -1, 0, 0], atol=1e-12)


def test_object_rot_ignores_pelvis_tilt(state, contract, motion):
    tilted = np.array([np.cos(0.15), np.sin(0.15), 0, 0])  # 0.3 rad roll on top of the yaw
    state.pelvis_quat_wxyz = np.array([
        YAW90[0] * tilted[0], YAW90[0] * tilted[1], YAW90[3] * tilted[1], YAW90[3] * tilted[0]])
    np.testing.assert_allclose(term("object_pos", state, contract, motion), [1.0, 0.0, 0.2], atol=1e-12)


def test_reference_terms_at_keyframes(state, contract, motion):
    # tick 0, keyframes (1, 16), 3 frames -> frames 1 and 2 (clamped)
    np.testing.assert_allclose(term("ref_root_pos", state, contract, motion), [0, -1, 0, 0, 0, 0.1], atol=1e-12)
    np.testing.assert_allclose(term("ref_root_rot", state, contract, motion),
                               [1, 0, 0, 0, 1, 0, 0, 1, 0, -1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(term("ref_joint_pos", state, contract, motion), [0.2] * 41 + [-0.1] * 41, atol=1e-12)
    num_links = len(contract.link_names)
    link = term("ref_link_pos", state, contract, motion).reshape(2, num_links, 3)
    np.testing.assert_allclose(link[0, :, 1], -1 - np.arange(num_links) * 0.01, atol=1e-12)  # frame 1: root + x
    np.testing.assert_allclose(link[0, :, 0], 0, atol=1e-12)
    np.testing.assert_allclose(link[1, :, 1], -np.arange(num_links) * 0.01, atol=1e-12)
    np.testing.assert_allclose(link[1, :, 2], 0.1, atol=1e-12)
    np.testing.assert_allclose(term("ref_object_pos", state, contract, motion), [2, 0, 0, 0, 0, -0.3], atol=1e-12)
    np.testing.assert_allclose(term("ref_object_rot", state, contract, motion),
                               [0, 1, 0, -1, 0, 0, 1, 0, 0, 0, 1, 0], atol=1e-12)


def test_reference_frames_clamp_at_the_end(state, contract, motion):
    state.tick = 10
    np.testing.assert_allclose(term("ref_joint_pos", state, contract, motion), [-0.1] * 82, atol=1e-12)


def test_builder_concatenates_in_obs_spec_order(state, contract, motion):
    builder = ObservationBuilder(contract, motion)
    obs = builder.build(state)
    assert obs.dtype == np.float32 and obs.shape == (contract.obs_dim,)
    expected = np.concatenate([TERM_FUNCTIONS[t.name](state, builder.ctx) for t in contract.obs_spec])
    np.testing.assert_allclose(obs, expected.astype(np.float32))
    start = 0
    for t in contract.obs_spec:
        if t.name == "hand_force":
            np.testing.assert_allclose(obs[start:start + 12], [0.981] * 6 + [-0.4905] * 6, rtol=1e-6)
        start += t.size


def test_builder_needs_a_motion_for_reference_terms(contract):
    with pytest.raises(DeployError, match="no motion was given"):
        ObservationBuilder(contract, None)


def test_builder_refuses_a_motion_of_another_layout(contract, motion):
    bad = ReferenceMotion(**{**{k: getattr(motion, k) for k in ("fps", "root_pos", "root_quat_wxyz", "link_pos",
                                                               "object_pos", "object_quat_wxyz")},
                             "joint_pos": motion.joint_pos[:, :29]})
    with pytest.raises(DeployError, match="29 columns"):
        ObservationBuilder(contract, bad)

"""Rotation helpers (wxyz quaternions) against known rotations."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.rotations import (
    gravity_in_body,
    quat_wxyz_from_axis_angle,
    quat_wxyz_multiply,
    quat_wxyz_to_matrix,
    rotation_6d,
    tilt_angle_between,
    yaw_matrix,
    yaw_of_quat_wxyz,
)


def test_quaternion_to_matrix_known_rotations():
    rz90 = quat_wxyz_from_axis_angle(np.array([0.0, 0, 1]), np.pi / 2)
    np.testing.assert_allclose(rz90, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)])
    np.testing.assert_allclose(quat_wxyz_to_matrix(rz90), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(quat_wxyz_to_matrix(2 * rz90), quat_wxyz_to_matrix(rz90))  # normalises


def test_multiply_composes_rotations():
    a = quat_wxyz_from_axis_angle(np.array([1.0, 0, 0]), 0.3)
    b = quat_wxyz_from_axis_angle(np.array([0.0, 1, 0]), -0.7)
    np.testing.assert_allclose(quat_wxyz_to_matrix(quat_wxyz_multiply(a, b)),
                               quat_wxyz_to_matrix(a) @ quat_wxyz_to_matrix(b), atol=1e-12)


@pytest.mark.parametrize("yaw", [-3.0, -1.0, 0.0, 0.5, 2.9])
def test_yaw_survives_tilt(yaw):
    q = quat_wxyz_multiply(quat_wxyz_from_axis_angle(np.array([0.0, 0, 1]), yaw),
                           quat_wxyz_from_axis_angle(np.array([1.0, 0, 0]), 0.4))
    assert yaw_of_quat_wxyz(q) == pytest.approx(yaw)
    np.testing.assert_allclose(yaw_matrix(yaw)[:2, :2], [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])


def test_rotation_6d_is_first_two_columns_column_major():
    m = np.arange(9.0).reshape(3, 3)
    np.testing.assert_array_equal(rotation_6d(m), [0, 3, 6, 1, 4, 7])


def test_gravity_and_tilt():
    np.testing.assert_allclose(gravity_in_body(np.array([1.0, 0, 0, 0])), [0, 0, -1])
    pitched = quat_wxyz_from_axis_angle(np.array([0.0, 1, 0]), 0.2)
    yawed = quat_wxyz_from_axis_angle(np.array([0.0, 0, 1]), 1.0)
    assert tilt_angle_between(pitched, np.array([1.0, 0, 0, 0])) == pytest.approx(0.2)
    assert tilt_angle_between(yawed, np.array([1.0, 0, 0, 0])) == pytest.approx(0.0, abs=1e-7)

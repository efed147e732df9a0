"""Rotation helpers in numpy for the runtime (deploy may not use scipy).

Quaternions here are always scalar-first **wxyz** (MuJoCo's and the Unitree IMU's convention) and the names say
so. All functions accept a trailing axis of size 4 (quaternions), 3 (vectors) or (3, 3) (matrices) and broadcast
over leading axes. The "heading frame" is the yaw-only frame of a body: rotate world vectors by Rz(yaw)^T.
"""

from __future__ import annotations

import numpy as np


def normalize_quat_wxyz(quat_wxyz: np.ndarray) -> np.ndarray:
    q = np.asarray(quat_wxyz, dtype=np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_wxyz_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix R (body -> world) of a unit quaternion wxyz; normalises first."""
    q = normalize_quat_wxyz(quat_wxyz)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - w * z)
    m[..., 0, 2] = 2 * (x * z + w * y)
    m[..., 1, 0] = 2 * (x * y + w * z)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - w * x)
    m[..., 2, 0] = 2 * (x * z - w * y)
    m[..., 2, 1] = 2 * (y * z + w * x)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def quat_wxyz_multiply(a_wxyz: np.ndarray, b_wxyz: np.ndarray) -> np.ndarray:
    """Hamilton product a * b (apply b first, then a)."""
    a = np.asarray(a_wxyz, dtype=np.float64)
    b = np.asarray(b_wxyz, dtype=np.float64)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_wxyz_from_axis_angle(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def yaw_of_quat_wxyz(quat_wxyz: np.ndarray) -> np.ndarray:
    """Heading angle: yaw = atan2(R[1,0], R[0,0]) of the body -> world rotation (z-up world)."""
    q = normalize_quat_wxyz(quat_wxyz)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def yaw_matrix(yaw: np.ndarray | float) -> np.ndarray:
    """Rz(yaw): the heading frame's rotation (heading -> world)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    m = np.zeros(yaw.shape + (3, 3))
    m[..., 0, 0] = c
    m[..., 0, 1] = -s
    m[..., 1, 0] = s
    m[..., 1, 1] = c
    m[..., 2, 2] = 1.0
    return m


def rotation_6d(matrix: np.ndarray) -> np.ndarray:
    """First two columns of a rotation matrix, column-major: [R00, R10, R20, R01, R11, R21]."""
    m = np.asarray(matrix)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def gravity_in_body(quat_wxyz: np.ndarray) -> np.ndarray:
    """Unit gravity direction expressed in the body frame: R^T @ [0, 0, -1]."""
    r = quat_wxyz_to_matrix(quat_wxyz)
    return -r[..., 2, :]


def tilt_angle_between(quat_a_wxyz: np.ndarray, quat_b_wxyz: np.ndarray) -> float:
    """Angle (rad) between the gravity directions two orientations imply: compares roll/pitch, ignores yaw."""
    ga = gravity_in_body(quat_a_wxyz)
    gb = gravity_in_body(quat_b_wxyz)
    return float(np.arccos(np.clip(np.dot(ga, gb), -1.0, 1.0)))

"""Batched rotation math in torch. Every quaternion here is **wxyz** (MuJoCo's convention).

Clip data is xyzw; convert at the boundary with `xyzw_to_wxyz`.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor


def xyzw_to_wxyz(q: Tensor) -> Tensor:
    return torch.cat([q[..., 3:4], q[..., :3]], dim=-1)


def wxyz_to_xyzw(q: Tensor) -> Tensor:
    return torch.cat([q[..., 1:], q[..., :1]], dim=-1)


def quat_mul(a: Tensor, b: Tensor) -> Tensor:
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        dim=-1,
    )


def quat_conj(q: Tensor) -> Tensor:
    return torch.cat([q[..., :1], -q[..., 1:]], dim=-1)


def quat_apply(q: Tensor, v: Tensor) -> Tensor:
    """Rotate vectors v by unit quaternions q (broadcasting over leading dims)."""
    # numpy's: torch.broadcast_shapes imports sympy on its first call (0.4-0.8 s of a one-env gate) and is 6x slower
    batch = np.broadcast_shapes(q.shape[:-1], v.shape[:-1])
    q, v = q.expand(*batch, 4), v.expand(*batch, 3)
    w, xyz = q[..., :1], q[..., 1:]
    t = 2.0 * torch.cross(xyz, v, dim=-1)
    return v + w * t + torch.cross(xyz, t, dim=-1)


def quat_apply_inverse(q: Tensor, v: Tensor) -> Tensor:
    return quat_apply(quat_conj(q), v)


def quat_to_matrix(q: Tensor) -> Tensor:
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(*q.shape[:-1], 3, 3)


def quat_to_tan_norm(q: Tensor) -> Tensor:
    """6-D rotation feature: the first two columns of the rotation matrix, column-major (x axis, then y axis)."""
    m = quat_to_matrix(q)
    return torch.cat([m[..., :, 0], m[..., :, 1]], dim=-1)


def yaw_quat(q: Tensor) -> Tensor:
    """The heading (rotation about world z) part of q."""
    w, x, y, z = q.unbind(-1)
    yaw = torch.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    half = 0.5 * yaw
    zeros = torch.zeros_like(half)
    return torch.stack([torch.cos(half), zeros, zeros, torch.sin(half)], dim=-1)


def quat_angle(q: Tensor) -> Tensor:
    """Rotation angle in [0, pi] of unit quaternions (sign-invariant)."""
    return 2.0 * torch.acos(q[..., 0].abs().clamp(max=1.0))


def quat_diff_angle(a: Tensor, b: Tensor) -> Tensor:
    """Angle of the relative rotation between a and b."""
    return quat_angle(quat_mul(quat_conj(a), b))


def quat_from_yaw(yaw: Tensor) -> Tensor:
    half = 0.5 * yaw
    zeros = torch.zeros_like(half)
    return torch.stack([torch.cos(half), zeros, zeros, torch.sin(half)], dim=-1)


def quat_to_rotvec(q: Tensor) -> Tensor:
    """Axis * angle (angle in [0, pi]) of unit wxyz quaternions (the shorter way round)."""
    q = torch.where(q[..., :1] < 0, -q, q)
    vec = q[..., 1:]
    sin_half = vec.norm(dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(sin_half, q[..., :1])
    return vec * torch.where(sin_half > 1e-8, angle / sin_half.clamp(min=1e-8), 2.0)  # small angles: 2 * vec

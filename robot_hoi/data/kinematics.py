"""Skeleton kinematics of the 52-body clip format: forward kinematics, joint rotations, bone offsets.

All quaternions here are xyzw (scipy). A bone offset is the child's position in its parent's frame:
offset[j] = inv(R_parent) @ (p_j - p_parent); for real clips it is constant over time (SMPL-X skeleton).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.data.layout import BODY_INDEX, BODY_PARENTS, NUM_BODIES

_PARENTS = np.asarray(BODY_PARENTS)


def _rot(quat_xyzw: np.ndarray) -> Rotation:
    return Rotation.from_quat(np.asarray(quat_xyzw, dtype=np.float64).reshape(-1, 4))


def forward_kinematics(root_pos: np.ndarray, body_quat_xyzw: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """World body positions (T, 52, 3) from the root position (T, 3), global body rotations (T, 52, 4) and the
    bone offsets (52, 3) (row 0 ignored) or (T, 52, 3)."""
    root_pos = np.asarray(root_pos, dtype=np.float64)
    num_frames = root_pos.shape[0]
    offsets = np.broadcast_to(np.asarray(offsets, dtype=np.float64), (num_frames, NUM_BODIES, 3))
    mats = _rot(body_quat_xyzw).as_matrix().reshape(num_frames, NUM_BODIES, 3, 3)
    pos = np.empty((num_frames, NUM_BODIES, 3))
    pos[:, 0] = root_pos
    for j in range(1, NUM_BODIES):  # parents always come before children in BODY_PARENTS
        p = _PARENTS[j]
        pos[:, j] = pos[:, p] + np.einsum("tij,tj->ti", mats[:, p], offsets[:, j])
    return pos


def bone_offsets(body_pos: np.ndarray, body_quat_xyzw: np.ndarray) -> np.ndarray:
    """Per-frame bone offsets (T, 52, 3) in the parent's frame; row 0 is zero."""
    body_pos = np.asarray(body_pos, dtype=np.float64)
    num_frames = body_pos.shape[0]
    parent_rot = _rot(np.asarray(body_quat_xyzw)[:, _PARENTS[1:]])
    delta = (body_pos[:, 1:] - body_pos[:, _PARENTS[1:]]).reshape(-1, 3)
    out = np.zeros((num_frames, NUM_BODIES, 3))
    out[:, 1:] = parent_rot.apply(delta, inverse=True).reshape(num_frames, NUM_BODIES - 1, 3)
    return out


def relative_rotvecs(body_quat_xyzw: np.ndarray) -> np.ndarray:
    """Joint rotations (T, 51, 3): rotation vector of inv(R_parent(j)) * R_j for bodies 1..51."""
    body_quat_xyzw = np.asarray(body_quat_xyzw, dtype=np.float64)
    num_frames = body_quat_xyzw.shape[0]
    parent = _rot(body_quat_xyzw[:, _PARENTS[1:]])
    child = _rot(body_quat_xyzw[:, 1:])
    return (parent.inv() * child).as_rotvec().reshape(num_frames, NUM_BODIES - 1, 3)


def global_quats_from_rotvecs(root_quat_xyzw: np.ndarray, dof_rotvec: np.ndarray) -> np.ndarray:
    """Global body rotations (T, 52, 4) xyzw from the root rotation and the joint rotation vectors."""
    num_frames = root_quat_xyzw.shape[0]
    local = Rotation.from_rotvec(np.asarray(dof_rotvec, dtype=np.float64).reshape(-1, 3))
    local_q = local.as_quat().reshape(num_frames, NUM_BODIES - 1, 4)
    glob = [Rotation.from_quat(root_quat_xyzw)]
    for j in range(1, NUM_BODIES):
        glob.append(glob[_PARENTS[j]] * Rotation.from_quat(local_q[:, j - 1]))
    return np.stack([g.as_quat() for g in glob], axis=1)


def rotvec_mismatch(dof_rotvec: np.ndarray, body_quat_xyzw: np.ndarray) -> tuple[float, int, int]:
    """Largest angle (rad) between the stored joint rotations and those implied by the global rotations, with
    the frame and body index where it occurs."""
    stored = Rotation.from_rotvec(np.asarray(dof_rotvec, dtype=np.float64).reshape(-1, 3))
    implied = Rotation.from_rotvec(relative_rotvecs(body_quat_xyzw).reshape(-1, 3))
    err = (stored.inv() * implied).magnitude().reshape(dof_rotvec.shape[0], NUM_BODIES - 1)
    flat = int(np.argmax(err))
    frame, joint = divmod(flat, NUM_BODIES - 1)
    return float(err[frame, joint]), frame, joint + 1


def make_quaternions_continuous(quat_xyzw: np.ndarray) -> tuple[np.ndarray, int]:
    """Flip q -> -q along axis 0 (time) so consecutive quaternions lie in the same hemisphere.

    Works for (T, 4) and (T, N, 4). Returns the fixed copy and how many sign changes were removed.
    """
    q = np.array(quat_xyzw, dtype=np.float64, copy=True)
    if q.shape[0] < 2:
        return q, 0
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = dots < 0.0
    # A sign change between t-1 and t flips every later frame too: cumulative parity decides each frame's sign.
    parity = np.concatenate([np.zeros_like(flips[:1]), np.cumsum(flips, axis=0) % 2 == 1], axis=0)
    q[parity] *= -1.0
    return q, int(flips.sum())


# Chain from the toes to the head used to estimate standing height from a skeleton.
_HEIGHT_CHAIN = ("L_Hip", "L_Knee", "L_Ankle", "L_Toe")
_SPINE_CHAIN = ("Torso", "Spine", "Chest", "Neck", "Head")
# Subject height / (head joint - toe joint height in the T-pose); mean over the OMOMO subjects with a known
# height (sub2 1.109, sub3 1.104, sub8 1.114 from their clips' skeletons): estimates land within ~1 %.
HEIGHT_PER_TPOSE_SPAN = 1.109


def tpose_span(offsets: np.ndarray) -> float:
    """Vertical distance (m) from the left toe joint to the head joint in the T-pose built from bone offsets."""
    offsets = np.asarray(offsets, dtype=np.float64)
    leg = sum(offsets[BODY_INDEX[n], 2] for n in _HEIGHT_CHAIN)
    spine = sum(offsets[BODY_INDEX[n], 2] for n in _SPINE_CHAIN)
    return float(spine - leg)


def estimate_height_from_offsets(offsets: np.ndarray) -> float:
    """Standing height (m) of the subject whose skeleton has these bone offsets (52, 3)."""
    return HEIGHT_PER_TPOSE_SPAN * tpose_span(offsets)

"""Observation terms, named as in training, and the one builder that concatenates them as obs_spec says.

Every term is a numpy function `term(state: RobotState, ctx: ObsContext) -> (size,)`. The training environment
implements the same math in torch; a parity test compares them, so each docstring states the exact formula.

Conventions used by all terms:
    quaternions are wxyz; R(q) is the body -> world rotation matrix of q.
    Heading frame: the yaw-only frame of the pelvis, H = Rz(yaw(q_pelvis)), with yaw(q) = atan2(R[1,0], R[0,0])
    and q_pelvis from the pose tracker. A world vector v is expressed in it as H^T v.
    rot6(M) = [M00, M10, M20, M01, M11, M21] (first two columns, column-major).
    Reference frames: t = the policy tick index (0 at the first POLICY tick); the reference clock holds frame 0
    for the contract's warmup_frames ticks, f(t) = max(t - warmup_frames, 0); for each k in keyframes, in order,
    frame f_k = min(f(t) + k, T - 1). Reference terms concatenate k-major: [value(f_k1), value(f_k2), ...].
    Joint vectors have the contract's actuator order: body joints, left hand channels, right hand channels.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from deploy.contract import OBS_TERMS, PolicyContract
from deploy.errors import DeployError
from deploy.hand_units import HAND_SIDES, channel_arrays, units_to_rad
from deploy.motion import ReferenceMotion
from deploy.rotations import gravity_in_body, quat_wxyz_to_matrix, rotation_6d, yaw_matrix, yaw_of_quat_wxyz

GRAMS_TO_DECINEWTON = 9.81e-3 / 10.0  # FORCE_ACT grams -> N, then / 10 to keep the term near unit scale


@dataclass
class RobotState:
    """One snapshot of everything the observation terms read (world frame, z up)."""

    joint_pos: np.ndarray  # (B,) body q, rad, Unitree motor order
    joint_vel: np.ndarray  # (B,) body dq, rad/s
    imu_quat_wxyz: np.ndarray  # (4,) pelvis IMU orientation
    gyro: np.ndarray  # (3,) pelvis angular velocity in the pelvis frame, rad/s
    hand_angles: np.ndarray  # (12,) ANGLE_ACT units 0..1000, left hand then right hand, register order
    hand_forces: np.ndarray  # (12,) FORCE_ACT grams, same order
    pelvis_pos: np.ndarray  # (3,) from the pose tracker
    pelvis_quat_wxyz: np.ndarray  # (4,) from the pose tracker
    object_pos: np.ndarray  # (3,)
    object_quat_wxyz: np.ndarray  # (4,)
    last_action: np.ndarray  # (A,) the policy's previous raw output
    tick: int  # policy tick index t into the reference motion


class ObsContext:
    """Constants the terms need, resolved once from the contract (and the motion, if any)."""

    def __init__(self, contract: PolicyContract, motion: ReferenceMotion | None):
        self.contract = contract
        self.motion = motion
        self.default_pose = contract.default_pose
        self.keyframes = np.asarray(contract.keyframes, dtype=np.int64)
        opens, closes = zip(*(channel_arrays(contract.hands[side]) for side in HAND_SIDES), strict=True)
        self.hand_open_rad = np.concatenate(opens)
        self.hand_closed_rad = np.concatenate(closes)

    def ref_frames(self, tick: int) -> np.ndarray:
        """f_k = min(f(t) + k, T - 1) for each keyframe k, f(t) = max(t - warmup_frames, 0)."""
        if self.motion is None:
            raise DeployError(f"{self.contract.source}: reference terms need a motion (none loaded)")
        frame = max(int(tick) - self.contract.warmup_frames, 0)
        return np.minimum(frame + self.keyframes, self.motion.num_frames - 1)


def heading_inverse(state: RobotState) -> np.ndarray:
    """H^T = Rz(yaw(q_pelvis))^T: rotates world vectors into the pelvis heading frame."""
    return yaw_matrix(yaw_of_quat_wxyz(state.pelvis_quat_wxyz)).T


def projected_gravity(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """R(q_imu)^T @ [0, 0, -1]: unit gravity direction in the pelvis frame."""
    return gravity_in_body(state.imu_quat_wxyz)


def base_ang_vel(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """gyro: pelvis angular velocity in the pelvis frame (rad/s), as the IMU reports it."""
    return np.asarray(state.gyro, dtype=np.float64)


def joint_pos(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """concat(q_body, q_hands) - default_pose, with q_hands = closed + ANGLE_ACT / 1000 * (open - closed)."""
    hands_rad = units_to_rad(state.hand_angles, ctx.hand_open_rad, ctx.hand_closed_rad)
    return np.concatenate([state.joint_pos, hands_rad]) - ctx.default_pose


def joint_vel(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """dq_body (rad/s); hand joint velocities are not observed."""
    return np.asarray(state.joint_vel, dtype=np.float64)


def hand_force(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """FORCE_ACT grams * 9.81e-3 / 10 (tenths of newtons), left hand then right hand."""
    return np.asarray(state.hand_forces, dtype=np.float64) * GRAMS_TO_DECINEWTON


def last_action(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """The policy's previous raw output (before clipping and scaling); zeros before the first policy tick."""
    return np.asarray(state.last_action, dtype=np.float64)


def object_pos(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """H^T (p_object - p_pelvis)."""
    return heading_inverse(state) @ (state.object_pos - state.pelvis_pos)


def object_rot(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """rot6(H^T R(q_object))."""
    return rotation_6d(heading_inverse(state) @ quat_wxyz_to_matrix(state.object_quat_wxyz))


def ref_root_pos(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """For each k: H^T (ref_root_pos[f_k] - p_pelvis)."""
    ref = ctx.motion.root_pos[ctx.ref_frames(state.tick)]
    return ((ref - state.pelvis_pos) @ heading_inverse(state).T).reshape(-1)


def ref_root_rot(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """For each k: rot6(H^T R(ref_root_quat_wxyz[f_k]))."""
    ref = quat_wxyz_to_matrix(ctx.motion.root_quat_wxyz[ctx.ref_frames(state.tick)])
    return rotation_6d(heading_inverse(state) @ ref).reshape(-1)


def ref_joint_pos(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """For each k: ref_joint_pos[f_k] - default_pose."""
    return (ctx.motion.joint_pos[ctx.ref_frames(state.tick)] - ctx.default_pose).reshape(-1)


def ref_link_pos(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """For each k, for each link l (link_names order): H^T (ref_link_pos[f_k, l] - p_pelvis); flattened k, l, xyz."""
    ref = ctx.motion.link_pos[ctx.ref_frames(state.tick)]
    return ((ref - state.pelvis_pos) @ heading_inverse(state).T).reshape(-1)


def ref_object_pos(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """For each k: H^T (ref_object_pos[f_k] - p_pelvis)."""
    ref = ctx.motion.object_pos[ctx.ref_frames(state.tick)]
    return ((ref - state.pelvis_pos) @ heading_inverse(state).T).reshape(-1)


def ref_object_rot(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """For each k: rot6(H^T R(ref_object_quat_wxyz[f_k]))."""
    ref = quat_wxyz_to_matrix(ctx.motion.object_quat_wxyz[ctx.ref_frames(state.tick)])
    return rotation_6d(heading_inverse(state) @ ref).reshape(-1)


def ref_root_local(state: RobotState, ctx: ObsContext) -> np.ndarray:
    """For each k: [G^T (ref_root_pos[f_k] - ref_root_pos[f_0]), rot6(G^T R(ref_root_quat_wxyz[f_k]))], f_0 =
    min(f(t), T - 1) the frame being tracked, G = Rz(yaw(ref_root_quat_wxyz[f_0])): where the reference's pelvis
    goes, seen from the reference itself. Reads no tracked pose (a policy without mocap)."""
    motion = ctx.motion
    frame0 = ctx.contract.reference_frame(state.tick, motion.num_frames)
    frames = ctx.ref_frames(state.tick)
    g_inv = yaw_matrix(yaw_of_quat_wxyz(motion.root_quat_wxyz[frame0])).T
    pos = (motion.root_pos[frames] - motion.root_pos[frame0]) @ g_inv.T
    rot = rotation_6d(g_inv @ quat_wxyz_to_matrix(motion.root_quat_wxyz[frames]))
    return np.concatenate([pos, rot], axis=1).reshape(-1)


TERM_FUNCTIONS: dict[str, Callable[[RobotState, ObsContext], np.ndarray]] = {
    "projected_gravity": projected_gravity,
    "base_ang_vel": base_ang_vel,
    "joint_pos": joint_pos,
    "joint_vel": joint_vel,
    "hand_force": hand_force,
    "last_action": last_action,
    "object_pos": object_pos,
    "object_rot": object_rot,
    "ref_root_pos": ref_root_pos,
    "ref_root_rot": ref_root_rot,
    "ref_joint_pos": ref_joint_pos,
    "ref_link_pos": ref_link_pos,
    "ref_object_pos": ref_object_pos,
    "ref_object_rot": ref_object_rot,
    "ref_root_local": ref_root_local,
}
assert set(TERM_FUNCTIONS) == set(OBS_TERMS), "observation registry and contract term table disagree"


class ObservationBuilder:
    """Builds the policy input exactly as the contract's obs_spec lists it."""

    def __init__(self, contract: PolicyContract, motion: ReferenceMotion | None = None):
        if contract.uses_reference and motion is None:
            raise DeployError(
                f"{contract.source}: obs_spec uses reference terms but no motion was given "
                "(pass --motion or ship the sidecar named in the policy's 'reference')"
            )
        if motion is not None:
            motion.check_against(contract)
        self.contract = contract
        self.ctx = ObsContext(contract, motion)
        self._terms = [(t.name, t.size, TERM_FUNCTIONS[t.name]) for t in contract.obs_spec]
        self._out = np.zeros(contract.obs_dim, dtype=np.float32)

    def terms(self, state: RobotState) -> dict[str, np.ndarray]:
        return {name: fn(state, self.ctx) for name, _, fn in self._terms}

    def build(self, state: RobotState) -> np.ndarray:
        start = 0
        for name, size, fn in self._terms:
            value = fn(state, self.ctx)
            if value.shape != (size,):
                raise DeployError(f"observation term '{name}' produced shape {value.shape}, contract says ({size},)")
            self._out[start : start + size] = value
            start += size
        return self._out.copy()

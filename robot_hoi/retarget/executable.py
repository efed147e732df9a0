"""Make an IK retarget executable by a PD-controlled robot: smooth joint tracks and a grasp that squeezes.

- Smoothing. Per-frame IK can jump between solutions (wrist roll flips by > 1 rad in one frame); a robot cannot
  follow that, and reference-state starts would copy the jump as a velocity. Body joint tracks are limited to
  `max_joint_speed` (forward and backward passes, so the limit holds without a phase lag) and then low-passed
  with a Gaussian of `smoothing_sigma_s`.
- Squeeze. Position targets that put the hands exactly on the object hold nothing: the PD servos produce force
  only from an error. While a hand holds the object, its arm's PD targets are moved so the hand would go
  `squeeze_depth` further toward the other hand (damped least squares on the wrist Jacobian of the shoulder and
  elbow joints). Only the PD targets (`joint_pos`) carry the squeeze; the reference states and link targets do
  not, so the rewards still ask for the hands on the surface.
- Load compensation. A PD servo settles where its error balances the load: with the G1's arm gains the bent-over
  arms sagged 9 cm below the reference and the gripped box hung at the hands' height instead of below the grip,
  tilted and slipped out. The waist and arm PD targets are offset by tau / kp, tau the static torque that holds the
  reference pose against gravity and, while the object is held above its resting height, against its weight
  shared by the holding hands (`compensate_loads`). Only the PD targets carry it, like the squeeze.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from robot_hoi.retarget.kinematics import joint_ids


@dataclass(frozen=True)
class ExecutableSettings:
    max_joint_speed: float = 12.0     # rad/s for the waist and arm joints (legs stay as solved)
    smoothing_sigma_s: float = 0.03   # s, Gaussian low-pass of those tracks (0: off)
    squeeze_depth: float = 0.06       # m the held hands' PD targets go past the surface, toward each other
    squeeze_damping: float = 1e-3     # damped least squares (m^2)
    compensate_loads: bool = True     # PD targets offset by the static gravity / held-object torque over kp


def limit_speed(track: np.ndarray, max_step: float) -> np.ndarray:
    """(T, J) track whose per-frame change is at most `max_step`: the mean of a forward and a backward pass."""
    fwd, bwd = track.copy(), track.copy()
    for t in range(1, len(track)):
        fwd[t] = fwd[t - 1] + np.clip(track[t] - fwd[t - 1], -max_step, max_step)
    for t in range(len(track) - 2, -1, -1):
        bwd[t] = bwd[t + 1] + np.clip(track[t] - bwd[t + 1], -max_step, max_step)
    out = 0.5 * (fwd + bwd)
    for t in range(1, len(out)):  # the mean of two limited tracks can still step a little too far
        out[t] = out[t - 1] + np.clip(out[t] - out[t - 1], -max_step, max_step)
    return out


def smooth_joints(qpos: np.ndarray, qadr: np.ndarray, fps: float, settings: ExecutableSettings) -> np.ndarray:
    """qpos (T, nq) with the joints at `qadr` speed-limited and low-passed; other entries unchanged."""
    out = qpos.copy()
    track = limit_speed(qpos[:, qadr], settings.max_joint_speed / fps)
    if settings.smoothing_sigma_s > 0 and len(track) > 2:
        track = gaussian_filter1d(track, settings.smoothing_sigma_s * fps, axis=0, mode="nearest")
    out[:, qadr] = track
    return out


def squeeze_offsets(model: mujoco.MjModel, qpos: np.ndarray, closure: dict[str, np.ndarray],
                    wrist_bodies: dict[str, str], arm_joints: dict[str, list[str]],
                    settings: ExecutableSettings) -> np.ndarray:
    """(T, nq) joint offsets for the PD targets: per side, scaled by that hand's closure (0..1, ramps in and out),
    the joint motion that moves its wrist `squeeze_depth` toward the other wrist."""
    data = mujoco.MjData(model)
    offsets = np.zeros_like(qpos)
    jac = np.zeros((3, model.nv))
    bodies = {side: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) for side, name in wrist_bodies.items()}
    joints = {side: joint_ids(model, names) for side, names in arm_joints.items()}
    for t in np.flatnonzero(sum(closure.values()) > 0):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        for side, other in (("left", "right"), ("right", "left")):
            if closure[side][t] <= 0:
                continue
            towards = data.xpos[bodies[other]] - data.xpos[bodies[side]]
            towards /= max(np.linalg.norm(towards), 1e-6)
            mujoco.mj_jacBody(model, data, jac, None, bodies[side])
            cols = model.jnt_dofadr[joints[side]]
            j = jac[:, cols]
            step = j.T @ np.linalg.solve(j @ j.T + settings.squeeze_damping * np.eye(3),
                                         closure[side][t] * settings.squeeze_depth * towards)
            offsets[t, model.jnt_qposadr[joints[side]]] = step
    return offsets


def load_offsets(model: mujoco.MjModel, qpos: np.ndarray, joints: list[str],
                 carried: dict[str, np.ndarray]) -> np.ndarray:
    """(T, nq) PD-target offsets tau / kp for the position-actuated `joints`: tau holds each pose (qvel 0) against
    gravity and against the weights `carried` {body: (T,) N, pulling down at that body's origin}."""
    data = mujoco.MjData(model)
    offsets = np.zeros_like(qpos)
    ids = joint_ids(model, joints)
    dofs, qadr = model.jnt_dofadr[ids], model.jnt_qposadr[ids]
    kp = np.zeros(len(ids))
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and model.actuator_trnid[a, 0] in ids:
            kp[list(ids).index(model.actuator_trnid[a, 0])] = model.actuator_gainprm[a, 0]
    driven = kp > 0
    bodies = {name: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) for name in carried}
    jac = np.zeros((3, model.nv))
    for t in range(len(qpos)):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)  # qvel stays 0: the bias below is gravity only
        tau = np.zeros(model.nv)
        mujoco.mj_rne(model, data, 0, tau)
        for name, weight in carried.items():
            if weight[t] > 0:  # the hand holds the weight up: tau += J^T (0, 0, w)
                mujoco.mj_jacBody(model, data, jac, None, bodies[name])
                tau += jac[2] * weight[t]
        offsets[t, qadr[driven]] = tau[dofs[driven]] / kp[driven]
    return offsets

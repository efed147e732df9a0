"""Make an IK retarget executable by a PD-controlled robot: smooth joint tracks and a grasp that squeezes.

- Smoothing. Per-frame IK can jump between solutions (wrist roll flips by > 1 rad in one frame); a robot cannot
  follow that, and reference-state starts would copy the jump as a velocity. Body joint tracks are limited to
  `max_joint_speed` (forward and backward passes, so the limit holds without a phase lag) and then low-passed
  with a Gaussian of `smoothing_sigma_s`.
- Squeeze. Position targets that put the hands exactly on the object hold nothing: the PD servos produce force
  only from an error. While a hand holds the object, its arm's PD targets are moved so the hand would go
  `squeeze_depth` further toward the other hand, or into the object's nearest face (`squeeze_toward`; damped
  least squares on the wrist Jacobian of the shoulder and elbow joints). Only the PD targets (`joint_pos`) carry
  the squeeze; the reference states and link targets do not, so the rewards still ask for the hands on the surface.
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

from robot_hoi.errors import UserError
from robot_hoi.retarget.kinematics import joint_ids


@dataclass(frozen=True)
class ExecutableSettings:
    max_joint_speed: float = 12.0     # rad/s for the waist and arm joints (legs stay as solved)
    smoothing_sigma_s: float = 0.03   # s, Gaussian low-pass of those tracks (0: off)
    squeeze_depth: float = 0.06       # m the held hands' PD targets go past the surface (see squeeze_toward)
    # "other_hand": toward the other wrist (a two-hand grip of a box's sides). "surface": into the object along the
    # inward normal of the face nearest the hand, so a push presses into the box (one hand too). A zero-residual
    # replay of sub8_largebox_000 (a two-hand push) from frame 30: "other_hand" left the box 19 cm behind the
    # reference after 0.8 s with no hand touching it, "surface" 16 cm with the hands touching part of the time (its
    # hands rest on the box's top edge and press down more than forward); a 4-minute teacher: 0.84 s both ways
    squeeze_toward: str = "other_hand"
    squeeze_damping: float = 1e-3     # damped least squares (m^2)
    compensate_loads: bool = True     # PD targets offset by the static gravity / held-object torque over kp
    # ... for the legs too: the torques that carry the body on the feet in contact with the floor. A crouched G1
    # then holds its pose (pelvis sag 9 cm -> 0.04 cm; test) and the walk replays (zero residual, pelvis held by
    # the assist) sag 14-18 cm instead of 47-49, but do not last longer (embedded:walk:0 57 vs 60 frames, walk:3
    # 58 vs 75: the swing foot lands short and the pelvis drifts sideways), and lift_place's replay ends earlier
    # (73 vs 86 frames). Off until a walking policy is trained with it; `--set retarget.leg_loads=true`.
    compensate_leg_loads: bool = False
    # ... and for the motion too: tau = M(q) qdd + C(q, qd) + g(q) along the reference (finite differences) plus the
    # servos' damping kv qd, the held object's weight as m (g + its vertical acceleration). Off: static loads only
    compensate_dynamics: bool = False
    support_height: float = 0.015     # m above the lowest sole point: sole points this low carry the body


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


SQUEEZE_TOWARD = ("other_hand", "surface")


def check_squeeze_toward(value: str, name: str) -> str:
    """A user-given squeeze direction (`name`: the flag or config key it came from)."""
    if value not in SQUEEZE_TOWARD:
        raise UserError(f"{name} must be one of {', '.join(SQUEEZE_TOWARD)}, got {value!r}")
    return value


def check_squeeze_depth(value: float, name: str) -> float:
    """A user-given squeeze depth in metres (`name`: the flag or config key it came from)."""
    if not 0.0 <= value <= 0.3:
        raise UserError(f"{name} must be within [0, 0.3] m (how far past the surface the hands squeeze), got {value}")
    return value


def squeeze_offsets(model: mujoco.MjModel, qpos: np.ndarray, closure: dict[str, np.ndarray],
                    wrist_bodies: dict[str, str], arm_joints: dict[str, list[str]],
                    settings: ExecutableSettings, directions: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """(T, nq) joint offsets for the PD targets: per side, scaled by that hand's closure (0..1, ramps in and out),
    the joint motion that moves its wrist `squeeze_depth` along `directions[side]` ((T, 3) world unit vectors),
    or toward the other wrist where none are given."""
    data = mujoco.MjData(model)
    offsets = np.zeros_like(qpos)
    jac = np.zeros((3, model.nv))
    bodies = {side: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) for side, name in wrist_bodies.items()}
    joints = {side: joint_ids(model, names) for side, names in arm_joints.items()}
    for t in np.flatnonzero(sum(closure.values()) > 0):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        for side in closure:
            if closure[side][t] <= 0:
                continue
            if directions is not None:
                towards = directions[side][t]
            else:
                other = next(o for o in bodies if o != side)
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
                 carried: dict[str, np.ndarray], soles: tuple[np.ndarray, np.ndarray] | None = None,
                 support_height: float = 0.015, motion: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(T, nq) PD-target offsets tau / kp for the position-actuated `joints`: tau holds each pose (qvel 0) against
    gravity and against the weights `carried` {body: (T,) N, pulling down at that body's origin}. With `motion`
    ((T, nv) qvel, (T, nv) qacc of the reference) tau also drives the motion (inverse dynamics) and cancels the
    servos' damping at the reference velocity (position actuators: force = kp (target - q) - kv qd).

    With `soles` (body ids (P,), body-frame points (P, 3): the feet's sole corners) the floor carries the robot:
    forces at the sole points within `support_height` of the lowest one balance the floating base (least-norm
    forces), and the joints get the torques that pass that load down to the feet (the legs' share)."""
    data = mujoco.MjData(model)
    offsets = np.zeros_like(qpos)
    ids = joint_ids(model, joints)
    dofs, qadr = model.jnt_dofadr[ids], model.jnt_qposadr[ids]
    kp, kv = np.zeros(len(ids)), np.zeros(len(ids))
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and model.actuator_trnid[a, 0] in ids:
            k = list(ids).index(model.actuator_trnid[a, 0])
            kp[k], kv[k] = model.actuator_gainprm[a, 0], -model.actuator_biasprm[a, 2]
    driven = kp > 0
    bodies = {name: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) for name in carried}
    jac = np.zeros((3, model.nv))
    for t in range(len(qpos)):
        data.qpos[:] = qpos[t]
        if motion is not None:
            data.qvel[:], data.qacc[:] = motion[0][t], motion[1][t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)  # without `motion` qvel stays 0: the bias below is gravity only
        tau = np.zeros(model.nv)
        mujoco.mj_rne(model, data, int(motion is not None), tau)
        if motion is not None:
            tau[dofs[driven]] += kv[driven] * data.qvel[dofs[driven]]
        for name, weight in carried.items():
            if weight[t] > 0:  # the hand holds the weight up: tau += J^T (0, 0, w)
                mujoco.mj_jacBody(model, data, jac, None, bodies[name])
                tau += jac[2] * weight[t]
        if soles is not None:
            tau -= _floor_support(model, data, tau, *soles, support_height)
        offsets[t, qadr[driven]] = tau[dofs[driven]] / kp[driven]
    return offsets


def _floor_support(model: mujoco.MjModel, data: mujoco.MjData, tau: np.ndarray, sole_body: np.ndarray,
                   sole_local: np.ndarray, support_height: float) -> np.ndarray:
    """J^T f (nv,) of the least-norm floor forces f at the supporting sole points that hold the floating base
    (the free joint's rows of `tau`, the bias the actuators cannot supply) still."""
    world = data.xpos[sole_body] + np.einsum("pij,pj->pi", data.xmat[sole_body].reshape(-1, 3, 3), sole_local)
    # a sole point's share fades smoothly with its height above the lowest one (a foot lifting off hands its load
    # over within support_height instead of dropping it in one frame, which would make the PD targets jump)
    share = np.clip(1.0 - (world[:, 2] - world[:, 2].min()) / support_height, 0.0, 1.0) ** 2
    support = np.flatnonzero(share > 1e-3)
    jacs = np.zeros((len(support), 3, model.nv))
    for k, i in enumerate(support):
        mujoco.mj_jac(model, data, jacs[k], None, world[i], int(sole_body[i]))
    base = jacs[:, :, :6].reshape(-1, 6).T                     # (6, 3S): forces -> base rows
    weight = np.repeat(share[support], 3)                      # least-norm in the metric 1/share
    forces = weight * (base.T @ np.linalg.lstsq((base * weight) @ base.T, tau[:6], rcond=None)[0])
    return jacs.reshape(-1, model.nv).T @ forces

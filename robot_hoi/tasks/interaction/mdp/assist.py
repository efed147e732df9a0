"""Assist wrenches, a training curriculum: PD wrenches pull the pelvis and the object toward their reference poses,
so an early policy survives long enough to learn the interaction; their level anneals to zero as training goes on.

Applied by the physics at every sub-step of a control step (MuJoCo xfrc_applied: world force + torque at the body's
centre of mass, held over the sub-steps). Never in eval, export or sim2sim: evaluation builds its env with
`assist.enabled` off, and checkpoints record the level reached.
"""

from __future__ import annotations

from dataclasses import replace

import torch
from torch import Tensor

from robot_hoi.utils.torch_rot import quat_conj, quat_mul, quat_to_rotvec


def pd_wrench(pos: Tensor, quat: Tensor, lin_vel: Tensor, ang_vel: Tensor, ref_pos: Tensor, ref_quat: Tensor,
              ref_lin_vel: Tensor, ref_ang_vel: Tensor, kp: float | Tensor, kd: float | Tensor, kp_rot: float | Tensor,
              kd_rot: float | Tensor) -> Tensor:
    """(N, 6) world force and torque toward a reference pose and velocity (all world frame, quaternions wxyz)."""
    force = kp * (ref_pos - pos) + kd * (ref_lin_vel - lin_vel)
    torque = kp_rot * quat_to_rotvec(quat_mul(ref_quat, quat_conj(quat))) + kd_rot * (ref_ang_vel - ang_vel)
    return torch.cat([force, torque], dim=-1)


def terminations_at(cfg, thresholds, level: float):
    """The termination thresholds at curriculum `level`: the object line widened by cfg.object_termination_margin x
    level (`thresholds` itself when there is nothing to widen)."""
    margin = cfg.object_termination_margin * level
    if margin <= 0.0:
        return thresholds
    return replace(thresholds, max_mean_object_point_error=thresholds.max_mean_object_point_error + margin)


def assist_wrench(env, level: float) -> Tensor:
    """(N, nbody, 6) the env's assist at `level` (1 = full gains): pelvis and object toward the reference frame."""
    cfg = env.cfg.assist
    wrench = torch.zeros(env.num_envs, env.scene.model.nbody, 6, device=env.device)
    ref = env.ref
    ref_root_vel = env.ref_robot_qvel[env.ref_index]
    ref_root_ang_world = (ref.root_rotmat @ ref_root_vel[:, 3:6, None])[..., 0]  # free joint: body-frame angular
    root_ang_world = (env.root_rotmat @ env.root_ang_vel[..., None])[..., 0]
    in_warmup = (env.warmup_left > 0)[:, None]
    ref_lin = torch.where(in_warmup, 0.0, ref_root_vel[:, 0:3])
    ref_ang = torch.where(in_warmup, 0.0, ref_root_ang_world)
    wrench[:, env.scene.pelvis_body_id] = level * pd_wrench(
        env.root_pos, env.root_quat, env.root_lin_vel, root_ang_world, ref.root_pos, ref.root_quat_wxyz,
        ref_lin, ref_ang, cfg.root_kp, cfg.root_kd, cfg.root_kp_rot, cfg.root_kd_rot)
    obj = level * pd_wrench(
        env.object_pos, env.object_quat, env.object_lin_vel, env.object_ang_vel, ref.object_pos,
        ref.object_quat_wxyz, env.ref_object_lin_vel[env.ref_index], env.ref_object_ang_vel[env.ref_index],
        cfg.object_kp, cfg.object_kd, cfg.object_kp_rot, cfg.object_kd_rot)
    obj[:, 2] += level * cfg.object_gravity_share * env.object_mass * 9.81  # carry part of the object's weight
    wrench[:, env.scene.object_body_id()] = obj
    return wrench * env.assisted[:, None, None]  # only the episodes drawn to be assisted


def grip_settle_wrench(env, omega: float = 20.0) -> Tensor:
    """(N, nbody, 6) after a reference start, the object held at its reference pose (weight carried, critically
    damped PD at `omega` rad/s) while the grasp loads: full on the first step, fading linearly to none over
    `init.grip_settle_frames` (state initialisation, not the curriculum: it runs at every assist level, also 0)."""
    wrench = torch.zeros(env.num_envs, env.scene.model.nbody, 6, device=env.device)
    body = env.scene.object_body_id()
    mass = env.object_mass[:, None]
    inertia = float(env.scene.model.body_inertia[body].mean()) * mass / env.scene.object_mass  # scales with mass
    hold = pd_wrench(env.object_pos, env.object_quat, env.object_lin_vel, env.object_ang_vel, env.ref.object_pos,
                     env.ref.object_quat_wxyz, env.ref_object_lin_vel[env.ref_index],
                     env.ref_object_ang_vel[env.ref_index], mass * omega**2, mass * 2 * omega, inertia * omega**2,
                     inertia * 2 * omega)
    hold[:, 2] += env.object_mass * 9.81
    share = env.grip_settle_left.float() / max(env.cfg.init.grip_settle_frames, 1)
    wrench[:, body] = share[:, None] * hold
    return wrench


def assist_level(cfg, total_samples: int) -> float:
    """The curriculum: initial_level, falling linearly to 0 over anneal_samples training samples."""
    if not cfg.enabled or cfg.anneal_samples <= 0:
        return 0.0
    return float(cfg.initial_level * max(0.0, 1.0 - total_samples / cfg.anneal_samples))

"""Observation terms (InterMimic Eq. 1), expressed in the robot's heading frame (yaw of the pelvis) relative to
the pelvis position. Each returns (num_envs, size).

Self state s^s: proprioception, object state, d_t (link -> nearest object surface point) and contact flags c_t.
Goal state s^g for each keyframe k: differences to the reference at t+k and the absolute reference values.
"""

from __future__ import annotations

import torch
from torch import Tensor

from robot_hoi.errors import UserError
from robot_hoi.utils.torch_rot import quat_apply_inverse

# Rotations arrive as matrices the env computes once per step (env.heading_matrix H = Rz(yaw of the pelvis),
# env.*_rotmat, reference.*_rotmat): every term below is then a few batched matmuls.


def _to_heading(env, vec: Tensor) -> Tensor:
    """World vectors (N, ..., 3) into the heading frame: H^T v (row form v^T H)."""
    n = vec.shape[0]
    return (vec.reshape(n, -1, 3) @ env.heading_matrix).reshape(vec.shape)


def _rot6(matrix: Tensor) -> Tensor:
    """rot6(M) = first two columns, column-major: [M00, M10, M20, M01, M11, M21]."""
    return matrix[..., :, :2].transpose(-1, -2).reshape(*matrix.shape[:-2], 6)


def _rot_in_heading(env, rotmat: Tensor) -> Tensor:
    """rot6(H^T R) for rotation matrices (N, ..., 3, 3)."""
    heading = env.heading_matrix.reshape((rotmat.shape[0],) + (1,) * (rotmat.dim() - 3) + (3, 3))
    return _rot6(heading.transpose(-1, -2) @ rotmat)


def _relative_rot6(rot_a: Tensor, rot_b: Tensor) -> Tensor:
    """rot6(R_a^T R_b): the rotation from a to b, in a's frame (theta_hat (-) theta of Eq. 1)."""
    return _rot6(rot_a.transpose(-1, -2) @ rot_b)


def _flat(x: Tensor) -> Tensor:
    return x.reshape(x.shape[0], -1)


# ---- self state ------------------------------------------------------------------------------------------------
def root_height(env) -> Tensor:
    return env.root_pos[:, 2:3]


def root_rotation(env) -> Tensor:
    return _rot_in_heading(env, env.root_rotmat)


def root_linear_velocity(env) -> Tensor:
    return _to_heading(env, env.root_lin_vel)


def root_angular_velocity(env) -> Tensor:
    return env.root_ang_vel  # pelvis frame, as an IMU gyro reports it


def joint_positions(env) -> Tensor:
    return env.joint_pos - env.default_joint_pos


def joint_velocities(env, scale: float = 0.1) -> Tensor:
    return scale * env.joint_vel


def link_positions(env) -> Tensor:
    return _flat(_to_heading(env, env.link_pos - env.root_pos[:, None]))


def link_rotations(env) -> Tensor:
    return _flat(_rot_in_heading(env, env.link_rotmat))


def link_velocities(env, scale: float = 0.1) -> Tensor:
    return scale * _flat(_to_heading(env, env.link_vel))


def object_state(env) -> Tensor:
    return torch.cat([
        _to_heading(env, env.object_pos - env.root_pos),
        _rot_in_heading(env, env.object_rotmat),
        _to_heading(env, env.object_lin_vel),
        _to_heading(env, env.object_ang_vel),
    ], dim=-1)


def surface_vectors(env) -> Tensor:
    return _flat(_to_heading(env, env.d))


def contact_flags(env) -> Tensor:
    return env.contact_found.float()


def last_action(env) -> Tensor:
    return env.last_actions


def warmup_phase(env) -> Tensor:
    return (env.warmup_left.float() / max(env.cfg.warmup_frames, 1))[:, None]


# ---- goal state, one block per keyframe ---------------------------------------------------------------------------
def reference_goal(env, k: int) -> Tensor:
    """s^g_{t,t+k}: differences to the reference at t+k and the reference's absolute values (heading frame)."""
    ref = env.reference_at(k)
    return torch.cat([
        _flat(_relative_rot6(env.link_rotmat, ref.link_rotmat)),
        _flat(_to_heading(env, ref.link_pos - env.link_pos)),
        _relative_rot6(env.object_rotmat, ref.object_rotmat),
        _to_heading(env, ref.object_pos - env.object_pos),
        _flat(_to_heading(env, ref.d_hat - env.d)),
        ref.hand_contact.float() - env.hand_contact_found.float(),
        _flat(_rot_in_heading(env, ref.link_rotmat)),
        _flat(_to_heading(env, ref.link_pos - env.root_pos[:, None])),
        _rot_in_heading(env, ref.object_rotmat),
        _to_heading(env, ref.object_pos - env.root_pos),
    ], dim=-1)


SELF_TERMS = (
    root_height, root_rotation, root_linear_velocity, root_angular_velocity, joint_positions, joint_velocities,
    link_positions, link_rotations, link_velocities, object_state, surface_vectors, contact_flags, last_action,
    warmup_phase,
)


# ---- compact teacher observation (env.teacher_obs "compact") ------------------------------------------------------
# Proprioception, the object and the hands' surface vectors, plus per keyframe the reference pelvis, joints, hand
# links and object relative to the robot's pelvis in its heading frame: ~400 numbers instead of ~1750. Everything
# the full set adds (all link poses, velocities and their references) follows from the joints and the pelvis.
def hand_surface_vectors(env) -> Tensor:
    return _flat(_to_heading(env, env.d[:, env.scene.hand_link_flat_ids]))


def hand_contact_flags(env) -> Tensor:
    return env.hand_contact_found.float()


def reference_compact(env, k: int) -> Tensor:
    """Reference at t+k relative to the robot: pelvis position and rotation, joints, hand links, object, and which
    hands must touch the object."""
    ref = env.reference_at(k)
    hands = env.scene.hand_link_flat_ids
    return torch.cat([
        _to_heading(env, ref.root_pos - env.root_pos),
        _rot_in_heading(env, ref.root_rotmat),
        ref.joint_pos - env.default_joint_pos,
        _flat(_to_heading(env, ref.link_pos[:, hands] - env.root_pos[:, None])),
        _to_heading(env, ref.object_pos - env.root_pos),
        _rot_in_heading(env, ref.object_rotmat),
        ref.hand_contact.float(),
    ], dim=-1)


COMPACT_SELF_TERMS = (
    root_height, root_rotation, root_linear_velocity, root_angular_velocity, joint_positions, joint_velocities,
    object_state, hand_surface_vectors, hand_contact_flags, last_action, warmup_phase,
)
TEACHER_OBS_SETS = {"full": (SELF_TERMS, reference_goal), "compact": (COMPACT_SELF_TERMS, reference_compact)}


def _teacher_terms(env):
    if env.cfg.teacher_obs not in TEACHER_OBS_SETS:
        raise ValueError(f"env.teacher_obs must be one of {sorted(TEACHER_OBS_SETS)}, not {env.cfg.teacher_obs!r}")
    return TEACHER_OBS_SETS[env.cfg.teacher_obs]


def teacher_observation(env) -> Tensor:
    self_terms, goal = _teacher_terms(env)
    parts = [term(env) for term in self_terms]
    parts += [goal(env, k) for k in env.cfg.keyframes]
    return torch.cat(parts, dim=-1)


def critic_extras(env) -> Tensor:
    """Privileged extras for the critic: clip phase and contact forces."""
    start = env.clip_start[env.clip_id]
    phase = ((env.ref_index - start).float() / (env.clip_end[env.clip_id] - start).clamp(min=1).float())[:, None]
    return torch.cat([phase, 0.01 * _flat(env.contact_force)], dim=-1)


def teacher_observation_spec(env) -> list[dict]:
    """Names and sizes of the policy observation, in order (exported with the policy)."""
    self_terms, goal = _teacher_terms(env)
    spec = [{"name": f"teacher.{term.__name__}", "size": int(term(env).shape[1])} for term in self_terms]
    spec += [{"name": f"teacher.{goal.__name__}_k{k}", "size": int(goal(env, k).shape[1])}
             for k in env.cfg.keyframes]
    return spec


# ---- deployable (student) observation: the exact math of deploy/observations.py, batched in torch ---------------
# Only what the robot measures (joints, pelvis IMU, Inspire angles and forces, tracked object and pelvis poses)
# plus the reference. deploy/observations.py documents each formula; tests/tasks compares both builders.
FINGER_CHANNEL_SENSORS = ("pinky", "ring", "middle", "index", "thumb", "thumb")  # Inspire register order


def projected_gravity(env) -> Tensor:
    gravity = torch.tensor([0.0, 0.0, -1.0], device=env.device).expand(env.num_envs, 3)
    return quat_apply_inverse(env.root_quat, gravity)


def base_ang_vel(env) -> Tensor:
    return env.root_ang_vel


def joint_pos(env) -> Tensor:
    return env.joint_pos - env.default_joint_pos


def joint_vel(env) -> Tensor:
    return env.joint_vel[:, env.body_actuator_ids]


def hand_force(env) -> Tensor:
    """Fingertip force per Inspire channel in tenths of newtons (FORCE_ACT grams * 9.81e-3 / 10 on hardware)."""
    return env.contact_force[:, env.hand_force_sensor_ids].norm(dim=-1) / 10.0


def last_action_term(env) -> Tensor:
    return env.last_actions


def object_pos(env) -> Tensor:
    return _to_heading(env, env.object_pos - env.root_pos)


def object_rot(env) -> Tensor:
    return _rot_in_heading(env, env.object_rotmat)


def _keyframe_stack(env, fn) -> Tensor:
    return torch.cat([fn(env.reference_at(k)) for k in env.cfg.student_keyframes], dim=-1)


def ref_root_pos(env) -> Tensor:
    return _keyframe_stack(env, lambda ref: _to_heading(env, ref.root_pos - env.root_pos))


def ref_root_rot(env) -> Tensor:
    return _keyframe_stack(env, lambda ref: _rot_in_heading(env, ref.root_rotmat))


def ref_joint_pos(env) -> Tensor:
    return _keyframe_stack(env, lambda ref: ref.joint_pos - env.default_joint_pos)


def ref_link_pos(env) -> Tensor:
    return _keyframe_stack(env, lambda ref: _flat(_to_heading(env, ref.link_pos - env.root_pos[:, None])))


def ref_object_pos(env) -> Tensor:
    return _keyframe_stack(env, lambda ref: _to_heading(env, ref.object_pos - env.root_pos))


def ref_object_rot(env) -> Tensor:
    return _keyframe_stack(env, lambda ref: _rot_in_heading(env, ref.object_rotmat))


def ref_root_local(env) -> Tensor:
    """The reference pelvis at t+k relative to the reference's own at t, in the reference's heading frame: no
    tracked pose in it (an actor for a robot without mocap)."""
    ref0, heading = env.ref, env.ref_heading_matrix  # heading: Rz(yaw of the reference root at t)
    pos = lambda ref: ((ref.root_pos - ref0.root_pos)[:, None] @ heading)[:, 0]  # noqa: E731  (H^T v, row form)
    return _keyframe_stack(env, lambda ref: torch.cat([pos(ref), _rot6(heading.transpose(-1, -2) @ ref.root_rotmat)],
                                                      dim=-1))


STUDENT_TERMS = {
    "projected_gravity": projected_gravity, "base_ang_vel": base_ang_vel, "joint_pos": joint_pos,
    "joint_vel": joint_vel, "hand_force": hand_force, "last_action": last_action_term, "object_pos": object_pos,
    "object_rot": object_rot, "ref_root_pos": ref_root_pos, "ref_root_rot": ref_root_rot,
    "ref_joint_pos": ref_joint_pos, "ref_link_pos": ref_link_pos, "ref_object_pos": ref_object_pos,
    "ref_object_rot": ref_object_rot, "ref_root_local": ref_root_local,
}
# The student's observation unless its config names others (env.student_obs_terms; the object_free student option
# drops every term that reads a tracked pose): proprioception, the tracked object and the reference around the
# tracked pelvis.
DEFAULT_STUDENT_TERMS = (
    "projected_gravity", "base_ang_vel", "joint_pos", "joint_vel", "hand_force", "last_action", "object_pos",
    "object_rot", "ref_root_pos", "ref_root_rot", "ref_joint_pos", "ref_link_pos", "ref_object_pos",
    "ref_object_rot",
)


# The sensor noise (env_cfg.RandomizationCfg key) each deployable term carries in training: encoders, IMU, mocap
# (a pelvis pose error moves every position relative to the pelvis; modelled as independent noise per entry).
STUDENT_NOISE = {
    "projected_gravity": "imu_rot_noise", "base_ang_vel": "gyro_noise", "joint_pos": "joint_pos_noise",
    "joint_vel": "joint_vel_noise", "object_pos": "tracker_pos_noise", "object_rot": "tracker_rot_noise",
    "ref_root_pos": "tracker_pos_noise", "ref_link_pos": "tracker_pos_noise", "ref_object_pos": "tracker_pos_noise",
    "ref_root_rot": "tracker_rot_noise", "ref_object_rot": "tracker_rot_noise",
}


def check_student_terms(names) -> None:
    unknown = [n for n in names if n not in STUDENT_TERMS]
    if unknown:
        raise UserError(f"env.student_obs_terms: unknown term(s) {', '.join(unknown)} (known: {', '.join(STUDENT_TERMS)})")


def student_observation(env) -> Tensor:
    return torch.cat([env.randomization.noisy(name, STUDENT_TERMS[name](env)) for name in env.cfg.student_obs_terms],
                     dim=-1)


def student_observation_spec(env) -> list[dict]:
    return [{"name": name, "size": int(STUDENT_TERMS[name](env).shape[1])} for name in env.cfg.student_obs_terms]

"""Reward costs (InterMimic Sec. 3.2, supp. D, and an anchor-relative set). Each returns a cost E >= 0 per env.

Two aggregations (env.reward_mode):
- "product" (InterMimic): R = exp(-sum_i lambda_i * E_i); one bad term zeroes the whole reward.
- "sum" (BeyondMimic-style): R = sum_i s_i exp(-lambda_i * E_i) / sum_i s_i, s_i = the term's `scale`; every term
  that is right pays on its own, so a policy still learns to balance while its hands are off.
The env logs exp(-lambda_i * E_i) of every term on its own.
A term of kind "penalty" is not exponentiated: it subtracts lambda_i * E_i from either aggregate (action rate,
joint limits: BeyondMimic's regularisers, which must keep costing however large they get).

Robot version (supp. F): positions and rotations of the robot links mapped to SMPL-X bodies, w_d from the
link-to-object distances of simulation and reference (Eq. 2). Rotation and position costs are w-weighted means
over links so the lambdas stay meaningful for any link count. `squared=True` uses squared errors (InterMimic's
public code); with lambda 10, a uniform 10 cm error then scores exp(-0.1) = 0.90 instead of exp(-3) = 0.05.
"""

from __future__ import annotations

import torch
from torch import Tensor

from robot_hoi.utils.torch_rot import quat_conj, quat_diff_angle, quat_mul, yaw_quat


def _error(x: Tensor, squared: bool) -> Tensor:
    return x.square() if squared else x


def link_position_cost(env, squared: bool = False, feet_weight: float = 0.0) -> Tensor:
    """E_p^h = <|p_hat - p|, w_d>. `feet_weight` adds that weight to each foot link before renormalising: w_d
    puts almost nothing on the feet while the hands are near the object, so nothing would teach the stance."""
    w = env.w_d
    if feet_weight:
        w = w + feet_weight * env.feet_link_mask
        w = w / w.sum(-1, keepdim=True)
    return (w * _error((env.ref.link_pos - env.link_pos).norm(dim=-1), squared)).sum(-1)


def link_rotation_cost(env) -> Tensor:
    """E_theta^h = <angle(theta_hat (-) theta), 1 - w_d>, normalised by sum(1 - w_d)."""
    weight = 1.0 - env.w_d
    angle = quat_diff_angle(env.ref.link_quat_wxyz, env.link_quat)
    return (weight * angle).sum(-1) / weight.sum(-1)


def interaction_geometry_cost(env, squared: bool = False) -> Tensor:
    """E_d = <|d_hat - d|, w_d> (interaction graph between links and the object surface)."""
    return (env.w_d * _error((env.ref.d_hat - env.d).norm(dim=-1), squared)).sum(-1)


def object_position_cost(env, squared: bool = False) -> Tensor:
    return _error((env.ref.object_pos - env.object_pos).norm(dim=-1), squared)


def object_rotation_cost(env, squared: bool = False) -> Tensor:
    return _error(quat_diff_angle(env.ref.object_quat_wxyz, env.object_quat), squared)


# ---- anchor-relative terms (mean squared errors; the "sum" aggregation) -------------------------------------------
def _in_heading(rotmat: Tensor, vec: Tensor) -> Tensor:
    """World vectors (N, L, 3) into the heading frames (N, 3, 3): row form v^T H."""
    return vec @ rotmat


def root_position_cost(env) -> Tensor:
    """|root - root_hat|^2 (world): where the robot stands and how high its pelvis is."""
    return (env.ref.root_pos - env.root_pos).square().sum(-1)


def root_orientation_cost(env) -> Tensor:
    """angle(root, root_hat)^2: the pelvis' full orientation (lean and heading)."""
    return quat_diff_angle(env.ref.root_quat_wxyz, env.root_quat).square()


def body_position_cost(env) -> Tensor:
    """Mean over the body links (no hands) of the squared error of their positions relative to the pelvis, each
    side in its own heading frame: the body's shape, independent of where the robot stands (BeyondMimic)."""
    ids = env.scene.body_link_ids
    sim = _in_heading(env.heading_matrix, env.link_pos[:, ids] - env.root_pos[:, None])
    ref = _in_heading(env.ref_heading_matrix, env.ref.link_pos[:, ids] - env.ref.root_pos[:, None])
    return (sim - ref).square().sum(-1).mean(-1)


def body_rotation_cost(env) -> Tensor:
    """Mean over the body links of angle(link, link_hat)^2 (world)."""
    ids = env.scene.body_link_ids
    return quat_diff_angle(env.ref.link_quat_wxyz[:, ids], env.link_quat[:, ids]).square().mean(-1)


def feet_position_cost(env) -> Tensor:
    """Mean squared world error of the foot links: planted feet stay where the reference plants them."""
    ids = env.scene.feet_link_ids
    return (env.ref.link_pos[:, ids] - env.link_pos[:, ids]).square().sum(-1).mean(-1)


def hand_position_cost(env) -> Tensor:
    """Mean squared world error of the hand links (wrists and fingertips): where the object is held."""
    ids = env.scene.hand_link_flat_ids
    return (env.ref.link_pos[:, ids] - env.link_pos[:, ids]).square().sum(-1).mean(-1)


def joint_position_cost(env) -> Tensor:
    """Mean squared error of the body joints to the reference state's (the retarget's posture; not to its PD
    targets, whose grasp squeeze and load offsets would charge a robot exactly on the reference)."""
    ids = env.body_actuator_ids
    return (env.ref.joint_state[:, ids] - env.joint_pos[:, ids]).square().mean(-1)


def link_velocity_cost(env) -> Tensor:
    """Mean over the body links of the squared error of their world linear velocities (BeyondMimic's body
    velocity term): the reference's timing, which positions alone reward only once the error has grown."""
    ids = env.scene.body_link_ids
    return (env.ref.link_vel[:, ids] - env.link_vel[:, ids]).square().sum(-1).mean(-1)


def joint_velocity_cost(env) -> Tensor:
    """Mean squared error of the body joints' velocities to the reference state's (with the pelvis' and the
    links' linear velocities it fixes the links' angular velocities, which no sensor here measures)."""
    ids = env.body_actuator_ids
    return (env.ref.joint_vel[:, ids] - env.joint_vel[:, ids]).square().mean(-1)


def _relative_to_root(heading: Tensor, root_pos: Tensor, pos: Tensor) -> Tensor:
    return _in_heading(heading, (pos - root_pos)[:, None])[:, 0]


def object_relative_position_cost(env) -> Tensor:
    """|p_o - p_o_hat|^2 with each object position relative to its own pelvis, in its heading frame: where the
    object is held, apart from where the robot stands (which root_position_cost scores)."""
    sim = _relative_to_root(env.heading_matrix, env.root_pos, env.object_pos)
    ref = _relative_to_root(env.ref_heading_matrix, env.ref.root_pos, env.ref.object_pos)
    return (sim - ref).square().sum(-1)


def object_relative_rotation_cost(env) -> Tensor:
    """angle(H^-1 q_o, H_hat^-1 q_o_hat)^2, H the pelvis' heading: the object's orientation in the robot's heading
    frame."""
    sim = quat_mul(quat_conj(yaw_quat(env.root_quat)), env.object_quat)
    ref = quat_mul(quat_conj(yaw_quat(env.ref.root_quat_wxyz)), env.ref.object_quat_wxyz)
    return quat_diff_angle(ref, sim).square()


def action_rate_cost(env) -> Tensor:
    """|a_t - a_{t-1}|^2 over every action (a penalty term): the jitter a real actuator pays for."""
    return (env.actions - env.last_actions).square().sum(-1)


def joint_limit_cost(env, soft_fraction: float = 0.9) -> Tensor:
    """Radians beyond the soft joint limits (the middle `soft_fraction` of each range; a penalty term), summed
    over the body joints: a robot pressing a joint stop wears it and loses its torque margin. A joint the
    reference itself takes past a soft limit may go as far (a robot on the reference costs nothing); not the
    fingers: an open Inspire hand rests on its stop."""
    ids = env.body_actuator_ids
    low, high = env.ctrl_low[ids], env.ctrl_high[ids]
    mid, half = 0.5 * (high + low), 0.5 * soft_fraction * (high - low)
    ref = env.ref.joint_state[:, ids]
    q = env.joint_pos[:, ids]
    below = (torch.minimum(mid - half, ref) - q).clamp(min=0.0)
    above = (q - torch.maximum(mid + half, ref)).clamp(min=0.0)
    return (below + above).sum(-1)


def link_acceleration_cost(env) -> Tensor:
    """E_e^h = sum |a_h| over mapped links (finite-difference accelerations)."""
    return env.link_acc.norm(dim=-1).sum(-1)


def object_acceleration_cost(env) -> Tensor:
    return env.object_acc.norm(dim=-1)


def contact_force_cost(env) -> Tensor:
    """E_e^c = max |f| over the robot's contact sensors (penalises abrupt, hard contact)."""
    return env.contact_force.norm(dim=-1).amax(-1)


def contact_promotion_cost(env, sigma_margin: float = 0.005) -> Tensor:
    """E_b^c (Eq. 3) for the hands: reference says contact, simulation has none."""
    return ((env.ref.hand_contact.float() - env.hand_contact_found.float()).abs() * env.ref.hand_contact).sum(-1)


def contact_penalty_cost(env, sigma_p: float = 0.1) -> Tensor:
    """E_p^c (Eq. 4) for the hands: contact where the reference hand is further than sigma_p from the object."""
    far = env.ref.hand_distance > sigma_p
    return (env.hand_contact_found.float() * far).sum(-1)


def hand_contact_cost(env) -> Tensor:
    """E_h^c (Eqs. 5-6): every finger of a hand that must touch the object should touch it."""
    need = env.ref.hand_contact.float().repeat_interleave(5, dim=-1)   # (N, 10) fingers of left then right
    return ((need - env.finger_contact_found.float()).abs() * need).sum(-1)


REWARD_TERMS = {
    f.__name__: f
    for f in (
        link_position_cost, link_rotation_cost, interaction_geometry_cost, object_position_cost,
        object_rotation_cost, link_acceleration_cost, object_acceleration_cost, contact_force_cost,
        contact_promotion_cost, contact_penalty_cost, hand_contact_cost, root_position_cost, root_orientation_cost,
        body_position_cost, body_rotation_cost, feet_position_cost, hand_position_cost, joint_position_cost,
        link_velocity_cost, joint_velocity_cost, object_relative_position_cost, object_relative_rotation_cost,
        action_rate_cost, joint_limit_cost,
    )
}


def aggregate(costs: dict[str, Tensor], weights: dict[str, float], mode: str = "product",
              scales: dict[str, float] | None = None,
              penalties: frozenset[str] = frozenset()) -> tuple[Tensor, dict[str, Tensor]]:
    """The total reward and each term's exp(-lambda E): "product" exp(-sum lambda E) or "sum" (normalised by the
    scales' total, so R stays in [0, 1] either way); then minus lambda E of each term in `penalties` (logged as
    that negative value)."""
    tracked = {name: cost for name, cost in costs.items() if name not in penalties}
    penalty = {name: -weights[name] * cost for name, cost in costs.items() if name in penalties}
    per_term = {name: torch.exp(-weights[name] * cost) for name, cost in tracked.items()}
    if mode == "product":
        exponent = sum(weights[name] * cost for name, cost in tracked.items())
        reward = torch.exp(-exponent)
    elif mode == "sum":
        scales = scales or {}
        total = sum(scales.get(name, 1.0) for name in tracked)
        reward = sum(scales.get(name, 1.0) * value for name, value in per_term.items()) / total
    else:
        raise ValueError(f"reward mode must be 'product' or 'sum', not {mode!r}")
    return reward + sum(penalty.values(), torch.zeros_like(reward)), per_term | penalty

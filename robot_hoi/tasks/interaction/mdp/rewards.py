"""Reward costs (InterMimic Sec. 3.2, supp. D). Each returns a cost E >= 0 per env; the env aggregates
R = exp(-sum_i lambda_i * E_i) and logs exp(-lambda_i * E_i) of every term on its own.

Robot version (supp. F): positions and rotations of the robot links mapped to SMPL-X bodies, w_d from the
link-to-object distances of simulation and reference (Eq. 2). Rotation and position costs are w-weighted means
over links so the lambdas stay meaningful for any link count.
"""

from __future__ import annotations

import torch
from torch import Tensor

from robot_hoi.utils.torch_rot import quat_diff_angle

_EPS = 1e-4


def link_position_cost(env) -> Tensor:
    """E_p^h = <|p_hat - p|, w_d>."""
    return (env.w_d * (env.ref.link_pos - env.link_pos).norm(dim=-1)).sum(-1)


def link_rotation_cost(env) -> Tensor:
    """E_theta^h = <angle(theta_hat (-) theta), 1 - w_d>, normalised by sum(1 - w_d)."""
    weight = 1.0 - env.w_d
    angle = quat_diff_angle(env.ref.link_quat_wxyz, env.link_quat)
    return (weight * angle).sum(-1) / weight.sum(-1)


def interaction_geometry_cost(env) -> Tensor:
    """E_d = <|d_hat - d|, w_d> (interaction graph between links and the object surface)."""
    return (env.w_d * (env.ref.d_hat - env.d).norm(dim=-1)).sum(-1)


def object_position_cost(env) -> Tensor:
    return (env.ref.object_pos - env.object_pos).norm(dim=-1)


def object_rotation_cost(env) -> Tensor:
    return quat_diff_angle(env.ref.object_quat_wxyz, env.object_quat)


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
        contact_promotion_cost, contact_penalty_cost, hand_contact_cost,
    )
}


def aggregate(costs: dict[str, Tensor], weights: dict[str, float]) -> tuple[Tensor, dict[str, Tensor]]:
    """Multiplicative exp aggregation; returns the total reward and each term's exp(-lambda E)."""
    exponent = torch.zeros_like(next(iter(costs.values())))
    per_term = {}
    for name, cost in costs.items():
        scaled = weights[name] * cost
        exponent = exponent + scaled
        per_term[name] = torch.exp(-scaled)
    return torch.exp(-exponent), per_term

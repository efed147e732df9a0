"""Early termination (supp. E.1) and interaction early termination (Sec. 3.2). Each returns a bool per env."""

from __future__ import annotations

from torch import Tensor


def link_deviation(env, threshold: float) -> Tensor:
    """Mapped links on average further than `threshold` from their reference."""
    return (env.ref.link_pos - env.link_pos).norm(dim=-1).mean(-1) > threshold


def root_too_low(env, threshold: float) -> Tensor:
    return env.root_pos[:, 2] < threshold


def object_deviation(env, threshold: float) -> Tensor:
    """Object surface points on average further than `threshold` from where the reference has them."""
    return (env.object_points_world - env.ref_object_points_world).norm(dim=-1).mean(-1) > threshold


def interaction_distance_deviation(env, threshold: float) -> Tensor:
    """w_d-weighted link-to-object distance differs from the reference's by more than `threshold`."""
    sim = (env.w_d * env.d.norm(dim=-1)).sum(-1)
    ref = (env.w_d * env.ref.d_hat.norm(dim=-1)).sum(-1)
    return (sim - ref).abs() > threshold


def contact_lost(env, max_frames: int) -> Tensor:
    """A required hand-object contact has been missing for more than `max_frames` consecutive frames."""
    return env.contact_loss_frames.amax(-1) > max_frames

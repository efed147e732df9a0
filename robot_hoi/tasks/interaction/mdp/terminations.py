"""Early termination (supp. E.1) and interaction early termination (Sec. 3.2) on the env's state. The conditions
themselves are the registered terms of robot_hoi.termination, shared with sim2sim."""

from __future__ import annotations

from torch import Tensor

from robot_hoi import termination


def measured(env) -> termination.Measured:
    """The quantities the conditions read, for the env's current state and reference frame."""
    return termination.Measured(
        link_error=termination.mean_link_error(env.link_pos, env.ref.link_pos),
        root_height=env.root_pos[:, 2],
        object_error=termination.mean_object_point_error(env.object_points_world, env.ref_object_points_world),
        interaction_error=termination.interaction_distance_error(env.w_d, env.d, env.ref.d_hat),
        contact_loss=env.contact_loss_frames,
    )


def interaction_terminations(env, th: termination.Thresholds) -> dict[str, Tensor]:
    """{condition: bool per env} for the env's current state and reference frame."""
    return termination.ended(th, measured(env))

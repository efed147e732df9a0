"""InterMimic's early termination (supp. E.1) and interaction early termination (Sec. 3.2), written once.

The training env calls these on batched torch tensors, sim2sim on numpy arrays: every function uses only the
operators both libraries share (arithmetic, comparisons, `.sum(-1)`, `.mean(-1)`, `.clip`, `&`, `~`), so the two can never
drift. No torch import here: sim2sim's workers run without torch.
"""

from __future__ import annotations

from dataclasses import dataclass

_EPS = 1e-4


@dataclass
class Thresholds:
    """The thresholds as written (configs/tasks/interaction.yaml `terminations`)."""

    max_mean_link_error: float = 0.5        # m, mapped links on average further than this from their reference
    min_root_height: float = 0.15           # m
    max_mean_object_point_error: float = 0.5  # m, object surface points deviate on average
    max_interaction_distance_error: float = 0.5  # m, w_d-weighted link-to-object distance vs the reference
    max_contact_loss_frames: int = 10       # a required hand contact missing for more than this many frames
    # A required hand contact also counts as kept while a hand link (wrist or fingertip) is within this distance
    # of the object surface: the retargeted hands rest ~1 cm off the hull, and a grip is a few mm of squeeze.
    contact_tolerance: float = 0.02
    # ... measured from where the reference's own hand links are (their distance to the surface + the tolerance):
    # the Inspire hand's links are not where a human hand's joints were, and on sub2_largetable_000's edge grip
    # the retargeted wrists and fingertips sit 5-8 cm off the table while their collision geometry is within a few
    # mm of it, so a policy tracking the reference exactly lost "contact" 10 frames after the grip began
    contact_from_reference: bool = True


def hand_link_groups(link_names) -> list[list[int]]:
    """Indices of the wrist + fingertip links of the left and the right hand in a link_map order."""
    return [[i for i, n in enumerate(link_names) if n.startswith(prefix) or n == wrist]
            for prefix, wrist in (("L_", "left_wrist_yaw_link"), ("R_", "right_wrist_yaw_link"))]


def norm(x):
    """Euclidean norm over the last axis (torch or numpy)."""
    return (x * x).sum(-1) ** 0.5


def interaction_weights(d, d_hat):
    """w_d (InterMimic Eq. 2): 0.5 * normalised 1/|d|^2 of the simulation + 0.5 * the same of the reference."""
    inv = 1.0 / (d * d).sum(-1).clip(min=_EPS)
    inv_hat = 1.0 / (d_hat * d_hat).sum(-1).clip(min=_EPS)
    return 0.5 * inv / inv.sum(-1)[..., None] + 0.5 * inv_hat / inv_hat.sum(-1)[..., None]


def mean_link_error(link_pos, ref_link_pos):
    return norm(ref_link_pos - link_pos).mean(-1)


def mean_object_point_error(points_world, ref_points_world):
    return norm(points_world - ref_points_world).mean(-1)


def interaction_distance_error(w_d, d, d_hat):
    """|<w_d, |d|> - <w_d, |d_hat|>|."""
    return abs((w_d * norm(d)).sum(-1) - (w_d * norm(d_hat)).sum(-1))


def contact_loss_count(count, need, touching, nearest_hand_distance, th: Thresholds, reference_distance):
    """Consecutive frames each required hand contact has been missing: +1 where needed and neither touching nor
    within `th.contact_tolerance` of the surface (beyond `reference_distance`, the reference hand's own distance,
    with `th.contact_from_reference`), else reset to 0. Shapes (..., 2) for left / right."""
    reach = reference_distance + th.contact_tolerance if th.contact_from_reference else th.contact_tolerance
    missing = need & ~(touching | (nearest_hand_distance < reach))
    return (count + 1) * missing


def reasons(th: Thresholds, link_error, root_height, object_error, interaction_error, contact_loss) -> dict:
    """{reason: bool per env}; the episode ends where any is true."""
    return {
        "link_deviation": link_error > th.max_mean_link_error,
        "root_too_low": root_height < th.min_root_height,
        "object_deviation": object_error > th.max_mean_object_point_error,
        "interaction_distance": interaction_error > th.max_interaction_distance_error,
        "contact_lost": _amax_last(contact_loss) > th.max_contact_loss_frames,
    }


def interaction_tracked(worst_object_error, worst_body_error, max_object_error: float, max_body_error: float):
    """The half of `interaction_success` that a plain success lacks: over the tracked steps (after the warmup) the
    worst mean object point error and the worst mean body-link error (hands excluded, as E_h) stayed within their
    bounds (m). Without it a policy that never lifts the object can still reach the clip's end."""
    return (worst_object_error <= max_object_error) & (worst_body_error <= max_body_error)


def _amax_last(x):
    return x.amax(-1) if hasattr(x, "amax") else x.max(-1)  # torch's max(-1) returns (values, indices)

"""InterMimic's early termination (supp. E.1) and interaction early termination (Sec. 3.2), written once.

The training env calls these on batched torch tensors, sim2sim on numpy arrays: every function uses only the
operators both libraries share (arithmetic, comparisons, `.sum(-1)`, `.mean(-1)`, `.clip`, `&`, `~`), so the two can never
drift. No torch import here: sim2sim's workers run without torch.

Each condition that ends an episode is a registered term: a short function over the measured quantities
(`Measured`, built by the env in mdp/terminations.py and by sim2sim's monitor) whose keyword arguments are its
parameters, read from the `Thresholds` by name. The five conditions below read its flat fields; a condition added
later is one function here, registered with @condition, and one config entry, `terminations.conditions.<name>`
holding its parameters (the entry switches it on), e.g.

    @condition
    def root_too_high(m: Measured, max_root_height: float):
        return m.root_height > max_root_height

    terminations:
      conditions: {root_too_high: {max_root_height: 1.2}}
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

_EPS = 1e-4


@dataclass
class Thresholds:
    """The conditions' parameters as written (configs/tasks/interaction.yaml `terminations`), plain values: e.g.
    InterMimic's own evaluation is Thresholds(max_mean_object_point_error=0.5, contact_tolerance=0.0,
    contact_from_reference=False)."""

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
    # Conditions registered beyond the five above, each switched on by its entry: name -> its parameters (those left
    # out take the function's defaults)
    conditions: dict[str, dict[str, float | int | bool]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, params in self.conditions.items():
            term = CONDITIONS.get(name)
            if term is None:
                raise ValueError(f"conditions.{name}: no such termination condition (registered: "
                                 f"{', '.join(CONDITIONS)})")
            unknown = sorted(set(params) - set(term.parameters))
            missing = [p for p in term.parameters if p not in params and p not in term.defaults]
            if unknown or missing:
                raise ValueError(f"conditions.{name}: parameters {', '.join(term.parameters)}"
                                 + (f"; unknown {', '.join(unknown)}" if unknown else "")
                                 + (f"; missing {', '.join(missing)}" if missing else ""))


@dataclass
class Measured:
    """What the conditions read, per env: torch tensors (training) or numpy values (sim2sim)."""

    link_error: Any         # m, mean distance of the mapped links from their reference (mean_link_error)
    root_height: Any        # m, the pelvis's height
    object_error: Any       # m, mean distance of the object's surface points from the reference's
    interaction_error: Any  # m, interaction_distance_error
    contact_loss: Any       # (..., 2) frames each required hand contact has been missing (contact_loss_count)


@dataclass(frozen=True)
class Condition:
    func: Callable[..., Any]      # (m: Measured, **parameters) -> bool per env
    parameters: tuple[str, ...]   # its keyword arguments, by name
    defaults: dict[str, Any]


CONDITIONS: dict[str, Condition] = {}  # name -> condition, in the order they are checked and reported


def condition(func: Callable[..., Any]) -> Callable[..., Any]:
    """Register `func(m: Measured, **parameters) -> bool per env` as the condition named as the function."""
    if func.__name__ in CONDITIONS:
        raise ValueError(f"termination condition {func.__name__!r} is registered already")
    params = list(inspect.signature(func).parameters.values())[1:]
    CONDITIONS[func.__name__] = Condition(func, tuple(p.name for p in params),
                                          {p.name: p.default for p in params if p.default is not p.empty})
    return func


@condition
def link_deviation(m: Measured, max_mean_link_error: float):
    return m.link_error > max_mean_link_error


@condition
def root_too_low(m: Measured, min_root_height: float):
    return m.root_height < min_root_height


@condition
def object_deviation(m: Measured, max_mean_object_point_error: float):
    return m.object_error > max_mean_object_point_error


@condition
def interaction_distance(m: Measured, max_interaction_distance_error: float):
    return m.interaction_error > max_interaction_distance_error


@condition
def contact_lost(m: Measured, max_contact_loss_frames: int):
    return _amax_last(m.contact_loss) > max_contact_loss_frames


_FIELDS = {f.name for f in fields(Thresholds)}


def ended(th: Thresholds, m: Measured) -> dict:
    """{condition: bool per env} for every condition `th` holds the parameters of (its entry in `th.conditions`,
    else its fields); the episode ends where any is true."""
    out = {}
    for name, term in CONDITIONS.items():
        if name in th.conditions:
            out[name] = term.func(m, **th.conditions[name])
        elif term.parameters and all(p in _FIELDS for p in term.parameters):
            out[name] = term.func(m, **{p: getattr(th, p) for p in term.parameters})
    return out


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
    """`ended` with the measured quantities given one by one."""
    return ended(th, Measured(link_error, root_height, object_error, interaction_error, contact_loss))


def interaction_tracked(worst_object_error, worst_body_error, max_object_error: float, max_body_error: float):
    """The half of `interaction_success` that a plain success lacks: over the tracked steps (after the warmup) the
    worst mean object point error and the worst mean body-link error (hands excluded, as E_h) stayed within their
    bounds (m). Without it a policy that never lifts the object can still reach the clip's end."""
    return (worst_object_error <= max_object_error) & (worst_body_error <= max_body_error)


def _amax_last(x):
    return x.amax(-1) if hasattr(x, "amax") else x.max(-1)  # torch's max(-1) returns (values, indices)

"""Finger poses for the retarget: open by default, closed while the hand holds the object.

The clips carry no finger motion (OMOMO has flat hands), so the fingers are not solved for: a hand counts as
holding when the mean anchor weight of its fingertip links exceeds `threshold`, and its fingers then move from
the open pose toward the closed pose. Fully closed Inspire fingers curl into the palm and cannot wrap a 0.47 m
box, so the default closes `closure` = 60 % of the stroke; set 1.0 for a full grip. The change is rate-limited
(`ramp_s` for a full stroke), as the real fingers need ~0.6 s per stroke, and so that qvel stays finite.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_hoi.errors import UserError


@dataclass(frozen=True)
class GraspRule:
    threshold: float = 0.5  # mean fingertip anchor weight above which the hand holds the object
    closure: float = 0.6  # fraction of the open->closed stroke used when holding
    ramp_s: float = 0.3  # seconds for a full open->closed stroke


def check_closure(value: float, name: str) -> float:
    """A user-given finger closure (`name`: the flag or config key it came from), which must be a stroke fraction."""
    if not 0.0 <= value <= 1.0:
        raise UserError(f"{name} must be within [0, 1] (a fraction of the finger stroke), got {value}")
    return value


@dataclass(frozen=True)
class HandJoints:
    """One hand's driven finger joints with their open and closed angles (rad)."""

    side: str
    joint_names: tuple[str, ...]
    open_rad: tuple[float, ...]
    closed_rad: tuple[float, ...]


def holding(anchor: np.ndarray, tip_columns: list[int], threshold: float) -> np.ndarray:
    """(T,) bool: the fingertips' mean anchor weight exceeds the threshold."""
    if not tip_columns:
        return np.zeros(anchor.shape[0], dtype=bool)
    return anchor[:, tip_columns].mean(axis=1) > threshold


def closure_profile(hold: np.ndarray, fps: float, rule: GraspRule) -> np.ndarray:
    """(T,) closure fraction in [0, rule.closure], moving at most closure / (ramp_s * fps) per frame."""
    goal = np.where(hold, rule.closure, 0.0)
    step = rule.closure / max(rule.ramp_s * fps, 1.0)
    out = np.zeros_like(goal)
    c = goal[0]
    for t, g in enumerate(goal):
        c += np.clip(g - c, -step, step)
        out[t] = c
    return out


def finger_angles(hand: HandJoints, closure: np.ndarray) -> np.ndarray:
    """(T,) closure -> (T, J) joint angles, linear between open and closed."""
    lo = np.asarray(hand.open_rad)
    hi = np.asarray(hand.closed_rad)
    return lo[None, :] + closure[:, None] * (hi - lo)[None, :]

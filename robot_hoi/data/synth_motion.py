"""Time tracks for synthetic clips: smooth ramps, keyframed curves and a footstep planner.

All in the "scene" frame: the person walks along +x, left is +y, z up, floor at z = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator


def ramp(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 before t0, 1 after t1, a C2-smooth (quintic) rise in between."""
    s = np.clip((np.asarray(t, dtype=np.float64) - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def ramps(t: np.ndarray, start: float, moves: list[tuple[float, float, float]]) -> np.ndarray:
    """A value that starts at `start` and glides to each `(t0, t1, value)` in turn with `ramp`."""
    out = np.full(np.shape(t), float(start))
    current = float(start)
    for t0, t1, value in moves:
        out = out + (value - current) * ramp(t, t0, t1)
        current = value
    return out


def keyframes(t: np.ndarray, keys: list[tuple[float, float]]) -> np.ndarray:
    """Monotone (PCHIP, no overshoot) curve through (time, value) keys, held constant outside them."""
    times = np.array([k[0] for k in keys], dtype=np.float64)
    values = np.array([k[1] for k in keys], dtype=np.float64)
    if len(keys) == 1:
        return np.full(np.shape(t), values[0])
    order = np.argsort(times, kind="stable")
    times, values = times[order], values[order]
    keep = np.concatenate([[True], np.diff(times) > 1e-9])
    curve = PchipInterpolator(times[keep], values[keep], extrapolate=False)
    return curve(np.clip(t, times[0], times[-1]))


@dataclass(frozen=True)
class Step:
    side: str  # "L" or "R": the foot that swings
    t0: float  # lift-off
    t1: float  # touch-down
    x_from: float
    x_to: float


@dataclass(frozen=True)
class Walk:
    steps: tuple[Step, ...]
    t_start: float
    t_end: float
    x_start: float
    x_end: float

    def pelvis_keys(self) -> list[tuple[float, float]]:
        """Pelvis x keys: over the middle of the feet after each touch-down, at the ends when standing."""
        keys = [(self.t_start, self.x_start)]
        feet = {"L": self.x_start, "R": self.x_start}
        for step in self.steps[:-1]:
            feet[step.side] = step.x_to
            keys.append((step.t1, 0.5 * (feet["L"] + feet["R"])))
        keys.append((self.t_end, self.x_end))
        return keys


def plan_walk(
    t_start: float, x_start: float, x_end: float, *, max_step: float, step_time: float, double_support: float,
    first: str = "L",
) -> Walk:  # fmt: skip
    """Alternating steps from feet side by side at x_start to feet side by side at x_end (station x, i.e. the
    pelvis position when standing over the feet); the last step brings the trailing foot alongside."""
    distance = x_end - x_start
    placements = max(2, math.ceil(abs(distance) / max_step) + 1)
    stride = distance / (placements - 1)
    other = {"L": "R", "R": "L"}
    steps, side, t = [], first, t_start
    feet = {"L": x_start, "R": x_start}
    for k in range(1, placements + 1):
        target = x_start + k * stride if k < placements else x_end
        steps.append(Step(side, t, t + step_time, feet[side], target))
        feet[side] = target
        t += step_time + double_support
        side = other[side]
    return Walk(tuple(steps), t_start, t - double_support, x_start, x_end)


def foot_tracks(
    t: np.ndarray, walks: list[Walk], x0: float, lift: float
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per foot (x station, lift height above its resting height) over time. Planted feet do not move."""
    out = {}
    for side in ("L", "R"):
        x = np.full(len(t), x0, dtype=np.float64)
        z = np.zeros(len(t))
        for walk in walks:
            for step in (s for s in walk.steps if s.side == side):
                s = ramp(t, step.t0, step.t1)
                during = (t >= step.t0) & (t <= step.t1)
                x = np.where(
                    t > step.t1, step.x_to, np.where(during, step.x_from + s * (step.x_to - step.x_from), x)
                )
                phase = np.clip((t - step.t0) / (step.t1 - step.t0), 0.0, 1.0)
                z = np.where(
                    during, lift * np.sin(np.pi * phase) * min(1.0, abs(step.x_to - step.x_from) / 0.2), z
                )
        out[side] = (x, z)
    return out

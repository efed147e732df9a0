"""Inspire hand channels and the units <-> radians mapping, shared by the contract, the config and the runtime.

Inspire ANGLE_SET / ANGLE_ACT are 0..1000 with 1000 = open. Each channel drives one actuated URDF joint linearly
(Unitree xr_teleoperate's convention):
    rad   = closed_rad + units / 1000 * (open_rad - closed_rad)
    units = 1000 * (rad - closed_rad) / (open_rad - closed_rad)
Channels are listed in Inspire register order: pinky, ring, middle, index, thumb_bend, thumb_rotate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

INSPIRE_CHANNELS = ("pinky", "ring", "middle", "index", "thumb_bend", "thumb_rotate")
HAND_SIDES = ("left", "right")
UNITS_OPEN = 1000
UNITS_CLOSED = 0


@dataclass(frozen=True)
class HandChannel:
    name: str
    joint: str
    open_rad: float
    closed_rad: float

    def to_dict(self) -> dict:
        return {"name": self.name, "joint": self.joint, "open_rad": self.open_rad, "closed_rad": self.closed_rad}


def channel_arrays(channels: Sequence[HandChannel]) -> tuple[np.ndarray, np.ndarray]:
    """(open_rad, closed_rad) arrays in channel order."""
    return (
        np.array([c.open_rad for c in channels], dtype=np.float64),
        np.array([c.closed_rad for c in channels], dtype=np.float64),
    )


def units_to_rad(units: np.ndarray, open_rad: np.ndarray, closed_rad: np.ndarray) -> np.ndarray:
    """ANGLE_ACT units (0..1000, 1000 = open) -> joint radians."""
    return closed_rad + np.asarray(units, dtype=np.float64) / UNITS_OPEN * (open_rad - closed_rad)


def rad_to_units(rad: np.ndarray, open_rad: np.ndarray, closed_rad: np.ndarray) -> np.ndarray:
    """Joint radians -> ANGLE_SET units, rounded to int and clamped to 0..1000."""
    units = UNITS_OPEN * (np.asarray(rad, dtype=np.float64) - closed_rad) / (open_rad - closed_rad)
    return np.clip(np.rint(units), UNITS_CLOSED, UNITS_OPEN).astype(np.int64)

"""The hand-bus contract shared by the runtime and every Inspire transport (RS485 frames, Modbus RTU, CAN).

Values are in Inspire register order and units: pinky, ring, middle, index, thumb_bend, thumb_rotate;
angles 0..1000 with 1000 = open; forces in grams at the fingertip.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass
class HandState:
    """One read-back cycle."""

    angles: np.ndarray  # (6,) int, ANGLE_ACT 0..1000 (1000 = open)
    forces: np.ndarray  # (6,) int, FORCE_ACT, grams at the fingertip (-4000..4000)
    errors: np.ndarray  # (6,) uint8 ERROR bits (tables.ERROR_BITS)
    status: np.ndarray  # (6,) uint8 STATUS (tables.STATUS_CODES)
    temperatures: np.ndarray  # (6,) uint8 deg C
    stamp: float  # time.monotonic() when the reply arrived

    @property
    def has_fault(self) -> bool:
        return bool(np.any(self.errors))


class HandBus(ABC):
    """One Inspire hand on one link. Methods raise deploy.errors.HandLinkError when the hand does not answer
    properly after the configured retries, and HandFaultError when it answers with error bits set."""

    side: str  # "left" | "right"

    @abstractmethod
    def connect(self) -> None:
        """Open the link and check that the hand answers."""

    @abstractmethod
    def disconnect(self) -> None:
        """Put the hand in its configured safe state (best effort), then close the link."""

    @property
    @abstractmethod
    def is_connected(self) -> bool: ...

    @abstractmethod
    def configure(self, force_limits: Sequence[int], speeds: Sequence[int]) -> None:
        """Write FORCE_SET (0..3000 g) and SPEED_SET (0..1000) for the six DoF."""

    @abstractmethod
    def clear_errors(self) -> None:
        """Write CLEAR_ERROR = 1 (over-temperature clears itself only once the motor cools)."""

    @abstractmethod
    def write_angles(self, units: Sequence[int]) -> None:
        """Write ANGLE_SET; values are rounded and clamped to 0..1000 here as well."""

    @abstractmethod
    def read_state(self) -> HandState:
        """Read ANGLE_ACT, FORCE_ACT, ERROR, STATUS and TEMP."""

"""First-order finger model behind the simulated Inspire hands.

Each DoF slews toward ANGLE_SET at a rate set by SPEED_SET (1000 = a full 0..1000 stroke in 0.6 s, as the
manual states for no load). An optional object blocks a finger at a contact angle: closing past it squeezes
with force = stiffness x penetration, and the finger stops where the force reaches FORCE_SET (STATUS 3).
A fingertip with error bits set stops moving until the bits are cleared.

An external physics (sim2sim) can take over the measurement with `set_measured` and read `commanded_angles`.
Time is read on demand, so no thread is needed; everything is guarded by one lock.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

import numpy as np

from deploy.hands import tables

FULL_STROKE_S = 0.6  # SPEED_SET 1000, no load
ANGLE_OPEN = 1000
FORCE_LIMIT_ACT = 4000  # FORCE_ACT range is +-4000 g
DEFAULT_FORCE_SET = 1000
DEFAULT_STIFFNESS = 20.0  # grams per angle unit past the contact angle
AT_TARGET_TOL = 0.5
SAMPLE_PERIOD_S = 0.0005  # reads this close together share one sample of the model


def _six(values, dtype=np.float64) -> np.ndarray:
    arr = np.asarray(values, dtype=dtype)
    if arr.shape == ():
        arr = np.full(tables.NUM_DOF, arr, dtype=dtype)
    if arr.shape != (tables.NUM_DOF,):
        raise ValueError(f"expected {tables.NUM_DOF} values, got shape {arr.shape}")
    return arr


class FingerModel:
    def __init__(
        self,
        angles: Sequence[float] | float = ANGLE_OPEN,
        temperature: float = 32.0,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._clock = clock
        self._lock = threading.Lock()
        self._t = clock()
        self.angle_set = np.full(tables.NUM_DOF, ANGLE_OPEN, dtype=np.int64)
        self.speed_set = np.full(tables.NUM_DOF, 1000, dtype=np.int64)
        self.force_set = np.full(tables.NUM_DOF, DEFAULT_FORCE_SET, dtype=np.int64)
        self._angles = _six(angles).copy()
        self._forces = np.zeros(tables.NUM_DOF)
        self._errors = np.zeros(tables.NUM_DOF, dtype=np.uint8)
        self._sticky = np.zeros(tables.NUM_DOF, dtype=np.uint8)
        self._temps = _six(temperature).copy()
        self._contact = np.full(tables.NUM_DOF, np.nan)  # object surface per finger, nan = nothing there
        self._stiffness = np.full(tables.NUM_DOF, DEFAULT_STIFFNESS)
        self._external = False
        self._version = 0  # bumped by every change, so a cached sample is never stale
        self._sample: tuple[int, float, dict] | None = None

    # ------------------------------------------------------------------ device side (register writes)
    def command(self, angle_set=None, speed_set=None, force_set=None) -> None:
        """Apply register writes; an ANGLE_SET element of -1 leaves that DoF alone, as on the real hand."""
        with self._lock:
            self._version += 1
            self._advance()
            if angle_set is not None:
                new = _six(angle_set, np.int64)
                self.angle_set = np.where(new == -1, self.angle_set, new)
            if speed_set is not None:
                self.speed_set = _six(speed_set, np.int64).copy()
            if force_set is not None:
                self.force_set = _six(force_set, np.int64).copy()

    def clear_errors(self) -> None:
        with self._lock:
            self._version += 1
            self._advance()
            self._errors &= self._sticky

    def measure(self) -> dict[str, list[int]]:
        """Everything the read-only registers report, at the current time. Like the hand's own sensor loop,
        one sample serves every read within SAMPLE_PERIOD_S unless something changed (a CAN state read is 7
        requests; re-integrating for each would only cost the simulator CPU)."""
        with self._lock:
            now = self._clock()
            if self._sample is not None:
                version, stamp, values = self._sample
                if version == self._version and 0.0 <= now - stamp < SAMPLE_PERIOD_S:
                    return values
            self._advance()
            angles = [min(max(int(round(a)), 0), ANGLE_OPEN) for a in self._angles.tolist()]
            forces = [
                min(max(int(round(f)), -FORCE_LIMIT_ACT), FORCE_LIMIT_ACT) for f in self._forces.tolist()
            ]
            values = {
                "ANGLE_ACT": angles,
                "FORCE_ACT": forces,
                "POS_ACT": [2 * (ANGLE_OPEN - a) for a in angles],  # stroke 0 = open .. 2000 = closed
                "CURRENT": [min(abs(f) // 4, 2000) for f in forces],
                "ERROR": self._errors.tolist(),
                "STATUS": self._status().tolist(),
                "TEMP": [min(max(int(round(t)), 0), 100) for t in self._temps.tolist()],
            }
            self._sample = (self._version, now, values)
            return values

    # ------------------------------------------------------------------ test and sim2sim side
    @property
    def commanded_angles(self) -> np.ndarray:
        with self._lock:
            return self.angle_set.copy()

    @property
    def angles(self) -> np.ndarray:
        with self._lock:
            self._advance()
            return self._angles.copy()

    @property
    def forces(self) -> np.ndarray:
        with self._lock:
            self._advance()
            return self._forces.copy()

    def place_object(self, contact_angles, stiffness: float | Sequence[float] = DEFAULT_STIFFNESS) -> None:
        """Put an object where finger i touches it at angle contact_angles[i] (nan or None = finger is free)."""
        contact = np.array(
            [np.nan if c is None else c for c in _six(contact_angles, object)], dtype=np.float64
        )
        with self._lock:
            self._version += 1
            self._advance()
            self._contact = contact
            self._stiffness = _six(stiffness).copy()

    def remove_object(self) -> None:
        self.place_object([None] * tables.NUM_DOF)

    def set_measured(self, angles, forces) -> None:
        """External physics owns the measurement from now on (until release_measured)."""
        with self._lock:
            self._version += 1
            self._external = True
            self._angles = _six(angles).copy()
            self._forces = _six(forces).copy()

    def release_measured(self) -> None:
        with self._lock:
            self._version += 1
            self._external = False
            self._t = self._clock()

    def set_error_bits(self, bits: int, fingers: Sequence[int] | None = None, sticky: bool = False) -> None:
        """OR `bits` into ERROR of the given fingers (all by default). Sticky bits survive CLEAR_ERROR."""
        idx = list(range(tables.NUM_DOF)) if fingers is None else list(fingers)
        with self._lock:
            self._version += 1
            self._advance()
            self._errors[idx] |= np.uint8(bits)
            if sticky:
                self._sticky[idx] |= np.uint8(bits)

    def release_sticky_errors(self) -> None:
        """The persistent cause is gone (e.g. the motor cooled); the bits still need CLEAR_ERROR."""
        with self._lock:
            self._version += 1
            self._sticky[:] = 0

    def set_temperature(self, celsius) -> None:
        with self._lock:
            self._version += 1
            self._temps = _six(celsius).copy()

    # ------------------------------------------------------------------ dynamics
    # Plain Python on six floats: numpy's per-call overhead would dominate at this size, and the device
    # thread runs this for every request.
    def _limit_angle(self) -> list[float]:
        """Smallest angle each finger may reach: where the object's reaction equals FORCE_SET."""
        out = []
        for contact, force, k in zip(
            self._contact.tolist(), self.force_set.tolist(), self._stiffness.tolist(), strict=True
        ):
            out.append(-math.inf if math.isnan(contact) else contact - force / k)
        return out

    def _advance(self) -> None:
        now = self._clock()
        dt = max(0.0, now - self._t)
        self._t = now
        if self._external or dt == 0.0:
            return
        angles = self._angles.tolist()
        forces = []
        limits = self._limit_angle()
        for i, (angle_set, speed, err, contact, k) in enumerate(
            zip(
                self.angle_set.tolist(),
                self.speed_set.tolist(),
                self._errors.tolist(),
                self._contact.tolist(),
                self._stiffness.tolist(),
                strict=True,
            )
        ):
            if not err:
                max_step = min(max(speed, 0), 1000) / 1000.0 * ANGLE_OPEN / FULL_STROKE_S * dt
                target = max(float(angle_set), limits[i])
                angles[i] += min(max(target - angles[i], -max_step), max_step)
            forces.append(0.0 if math.isnan(contact) else k * max(0.0, contact - angles[i]))
        self._angles = np.array(angles)
        self._forces = np.array(forces)

    def _status(self) -> np.ndarray:
        status = []
        limits = self._limit_angle()
        for angle, angle_set, err, limit in zip(
            self._angles.tolist(), self.angle_set.tolist(), self._errors.tolist(), limits, strict=True
        ):
            if err:
                status.append(255)
            elif abs(angle - angle_set) <= AT_TARGET_TOL:
                status.append(tables.STATUS_AT_TARGET)
            elif angle_set < limit and abs(angle - limit) <= AT_TARGET_TOL:
                status.append(tables.STATUS_AT_FORCE_LIMIT)
            elif angle_set < angle:
                status.append(tables.STATUS_GRASPING)
            else:
                status.append(tables.STATUS_RELEASING)
        return np.array(status, dtype=np.int64)

"""Both Inspire hands as the runtime sees them: two HandBus links, unit conversion, safe state, fault reporting.

The runtime exchanges with the hands once per tick, pipelined: at the end of tick k it calls
`begin_cycle(targets)` (write ANGLE_SET, then read the state back), and at the start of tick k+1
`finish_cycle()` collects what came back. With `threaded=True` each hand's serial/CAN traffic runs on its own
worker thread during the loop's sleep, so two hands at 115200 baud fit a 50 Hz loop; with `threaded=False` the
exchange runs inline (deterministic, for fake-clock tests).

Freshness: a hand is judged by its own replies. Each side remembers when it was last asked (`asked_at`) and
when it last answered with a good reading (`stamp`); its age is zero while its latest request is answered and
otherwise how long that request has gone unanswered, so a late loop wake-up (which delays the asking, not the
answer) is never blamed on the hands. Before the first request the age is that of the reading from connect().

Readings are range-checked before anything uses them: a value outside its register's range (ANGLE_ACT 0..1000,
FORCE_ACT -4000..4000, TEMP 0..100) is a named fault (hand, finger, register, value) and the reading is dropped.

Failures: the bus already retries (and reopens a lost port). If it still raises HandLinkError, the side tries one
reconnect in the same cycle; if that fails the side is "link lost" and the reading carries a fault (the runtime
goes to DAMP). HandFaultError (error bits) is a fault too; its measurements are still used. While in the safe
state, lost links are retried every `reconnect_interval_s` and error bits cleared; after a reconnect the safe pose
is asserted again. Safe state: "hold" re-sends the last commanded angles (a grasped box is not dropped), "open"
opens the hand.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field

import numpy as np

from deploy.clock import Clock, MonotonicClock
from deploy.errors import DeployError, HandFaultError, HandLinkError
from deploy.hand_units import (
    HAND_SIDES,
    INSPIRE_CHANNELS,
    UNITS_OPEN,
    HandChannel,
    channel_arrays,
    rad_to_units,
    units_to_rad,
)
from deploy.hands.tables import REGISTERS

log = logging.getLogger("deploy.hands.pair")

SAFE_STATES = ("hold", "open")
NEVER = float("-inf")
DOF = 6


@dataclass
class HandsReading:
    angles: np.ndarray  # (12,) ANGLE_ACT units, left then right
    forces: np.ndarray  # (12,) FORCE_ACT grams
    errors: np.ndarray  # (12,) ERROR bits
    stamps: np.ndarray  # (2,) runtime clock time of each side's last good read (NEVER if none)
    ages: np.ndarray  # (2,) s each side has left its latest request unanswered (0: answered)
    rad: np.ndarray  # (12,) the angles as joint radians
    faults: list[str] = field(default_factory=list)  # problems the runtime must act on, e.g. "left: link lost: ..."
    every_n_ticks: int = 1  # the hands are exchanged every n-th tick: an answer may take n periods


@dataclass
class SideStats:
    cycles: int = 0
    link_errors: int = 0
    fault_errors: int = 0
    reconnects: int = 0
    reconnect_failures: int = 0
    late_cycles: int = 0  # exchange not finished when the next tick collected it
    reading_faults: int = 0  # readings dropped for a value outside its register's range
    commands: int = 0  # ANGLE_SET targets the hand acknowledged


CHECKED_READINGS = (("ANGLE_ACT", "angles"), ("FORCE_ACT", "forces"), ("TEMP", "temperatures"))


def reading_problem(state) -> str | None:
    """'reading out of range: index ANGLE_ACT = 4000 (valid 0..1000)' for the first bad value, else None."""
    for register, attribute in CHECKED_READINGS:
        reg = REGISTERS[register]
        values = np.asarray(getattr(state, attribute))
        bad = np.flatnonzero((values < reg.low) | (values > reg.high))
        if len(bad):
            i = int(bad[0])
            return f"reading out of range: {INSPIRE_CHANNELS[i]} {register} = {int(values[i])} (valid {reg.low}..{reg.high})"
    return None


class HandSide:
    """One hand: its bus, cached measurements, the last safe command and its link status."""

    def __init__(self, bus, clock: Clock, force_limits: np.ndarray, speeds: np.ndarray, safe_state: str,
                 reconnect_interval_s: float):
        self.bus = bus
        self.side = bus.side
        self.clock = clock
        self.force_limits = force_limits
        self.speeds = speeds
        self.safe_state = safe_state
        self.reconnect_interval_s = reconnect_interval_s
        self.angles = np.full(DOF, UNITS_OPEN, dtype=np.int64)
        self.forces = np.zeros(DOF, dtype=np.int64)
        self.errors = np.zeros(DOF, dtype=np.uint8)
        self.stamp = NEVER
        self.asked_at = NEVER
        self.last_sent: np.ndarray | None = None
        self.link_lost: str | None = None
        self.device_fault: str | None = None
        self.reading_fault: str | None = None
        self.command_times: deque[float] = deque(maxlen=4096)
        self.safe_pending = False
        self._last_recovery_try = NEVER
        self.stats = SideStats()

    def setup(self) -> None:
        """Connect, clear errors, write force limits and speeds, read a first state. Errors propagate."""
        self.bus.connect()
        self.bus.clear_errors()
        self.bus.configure(self.force_limits.tolist(), self.speeds.tolist())
        self._read()

    def _read(self) -> None:
        try:
            state = self.bus.read_state()
            self.device_fault = None
        except HandFaultError as exc:
            self.stats.fault_errors += 1
            self.device_fault = str(exc)
            state = getattr(exc, "state", None)
            if state is None:
                return
        self.reading_fault = reading_problem(state)
        if self.reading_fault is not None:
            self.stats.reading_faults += 1
            return
        self.angles = np.asarray(state.angles, dtype=np.int64)
        self.forces = np.asarray(state.forces, dtype=np.int64)
        self.errors = np.asarray(state.errors, dtype=np.uint8)
        if np.any(self.errors) and self.device_fault is None:
            self.device_fault = f"{self.side} hand reports error bits {self.errors.tolist()}"
        self.stamp = self.clock.now()

    def age(self, now: float) -> float:
        """0 while the latest request is answered; otherwise how long it has gone unanswered."""
        if self.asked_at == NEVER:
            return now - self.stamp
        return 0.0 if self.stamp >= self.asked_at else now - self.asked_at

    def command_rate(self, now: float, window_s: float) -> float:
        """Acknowledged ANGLE_SET commands per second over the last window_s (newest first: O(rate x window))."""
        count = 0
        for t in reversed(self.command_times):
            if t <= now - window_s:
                break
            count += 1
        return count / window_s

    def _safe_units(self) -> np.ndarray | None:
        if self.safe_state == "open":
            return np.full(DOF, UNITS_OPEN, dtype=np.int64)
        return None if self.last_sent is None else self.last_sent.copy()

    def _reconnect(self) -> None:
        if hasattr(self.bus, "reconnect"):
            self.bus.reconnect()
        else:
            try:
                self.bus.disconnect()
            except (HandLinkError, HandFaultError):
                pass
            self.bus.connect()
        self.bus.configure(self.force_limits.tolist(), self.speeds.tolist())
        self.stats.reconnects += 1

    def cycle(self, targets: np.ndarray | None) -> None:
        """One exchange (runs on the worker): recover if needed, write targets or the safe pose, read back."""
        self.stats.cycles += 1
        now = self.clock.now()
        if self.link_lost is not None:
            if now - self._last_recovery_try < self.reconnect_interval_s:
                return
            self._last_recovery_try = now
            try:
                self._reconnect()
            except (HandLinkError, HandFaultError, DeployError) as exc:
                self.stats.reconnect_failures += 1
                log.debug("%s hand: reconnect failed: %s", self.side, exc)
                return
            self.link_lost = None
            self.safe_pending = True  # the link was lost in a fault: assert the safe pose again
            log.info("%s hand: link restored", self.side)
        elif self.device_fault is not None and targets is None and now - self._last_recovery_try >= self.reconnect_interval_s:
            self._last_recovery_try = now
            try:
                self.bus.clear_errors()
            except (HandLinkError, HandFaultError) as exc:
                log.debug("%s hand: clear_errors failed: %s", self.side, exc)
        try:
            if self.safe_pending:
                units = self._safe_units()
                if units is not None:
                    self.bus.write_angles(units.tolist())
                self.safe_pending = False
            elif targets is not None:
                self.bus.write_angles(targets.tolist())
                self.last_sent = targets.copy()
                self.stats.commands += 1
                self.command_times.append(self.clock.now())
            self._read()
        except HandLinkError as exc:
            self.stats.link_errors += 1
            log.warning("%s hand: %s; reconnecting", self.side, exc)
            try:
                self._reconnect()
                self._read()
            except (HandLinkError, HandFaultError, DeployError) as exc2:
                self.stats.reconnect_failures += 1
                self.link_lost = f"{exc}; reconnect failed: {exc2}"
                self._last_recovery_try = self.clock.now()
        except HandFaultError as exc:  # raised by a write the device rejected
            self.stats.fault_errors += 1
            self.device_fault = str(exc)


class Hands:
    def __init__(
        self,
        left,
        right,
        channels: dict[str, Sequence[HandChannel]],
        *,
        clock: Clock | None = None,
        force_limits: Sequence[int] = (1000,) * DOF,
        speeds: Sequence[int] = (1000,) * DOF,
        safe_state: str = "hold",
        threaded: bool = True,
        reconnect_interval_s: float = 0.5,
        every_n_ticks: int = 1,
    ):
        if safe_state not in SAFE_STATES:
            raise DeployError(f"hand safe state must be one of {SAFE_STATES}, got {safe_state!r}")
        for bus, side in ((left, "left"), (right, "right")):
            if bus.side != side:
                raise DeployError(f"the {side} hand bus says it is the {bus.side} hand")
        self.clock = clock or MonotonicClock()
        forces = np.asarray(force_limits, dtype=np.int64)
        speeds_arr = np.asarray(speeds, dtype=np.int64)
        self.sides = [HandSide(bus, self.clock, forces, speeds_arr, safe_state, reconnect_interval_s)
                      for bus in (left, right)]
        opens, closes = zip(*(channel_arrays(channels[s]) for s in HAND_SIDES), strict=True)
        self.open_rad = np.concatenate(opens)
        self.closed_rad = np.concatenate(closes)
        self.threaded = threaded
        self.every_n_ticks = max(1, int(every_n_ticks))  # exchange every n-th tick (start-up bus budget)
        self._cycle_calls = 0
        self._executors = [ThreadPoolExecutor(1, thread_name_prefix=f"hand-{s.side}") for s in self.sides] \
            if threaded else []
        self._pending: list[Future | None] = [None, None]

    def connect(self) -> None:
        for side in self.sides:
            side.setup()

    def close(self) -> None:
        """Wait for running exchanges, then disconnect both hands (the buses apply their safe pose)."""
        for i, future in enumerate(self._pending):
            if future is not None:
                try:
                    future.result(timeout=1.0)
                except FutureTimeout:
                    log.warning("%s hand: exchange still running at shutdown", self.sides[i].side)
        for executor in self._executors:
            executor.shutdown(wait=True, cancel_futures=True)
        for side in self.sides:
            try:
                side.bus.disconnect()
            except (HandLinkError, HandFaultError) as exc:
                log.warning("%s hand: disconnect: %s", side.side, exc)

    def units_from_rad(self, rad: np.ndarray) -> np.ndarray:
        """(12,) joint radians -> ANGLE_SET units, clamped to 0..1000."""
        return rad_to_units(rad, self.open_rad, self.closed_rad)

    def rad_from_units(self, units: np.ndarray) -> np.ndarray:
        return units_to_rad(units, self.open_rad, self.closed_rad)

    def request_safe_state(self) -> None:
        """The next cycle writes the safe pose once (hold: last command again; open: 1000s) instead of targets."""
        for side in self.sides:
            side.safe_pending = True

    def begin_cycle(self, targets_units: np.ndarray | None) -> None:
        """Start the write + read exchange; targets (12,) units or None (read only)."""
        self._cycle_calls += 1
        safe_pending = any(side.safe_pending for side in self.sides)
        if (self._cycle_calls - 1) % self.every_n_ticks and not safe_pending:
            return
        for i, side in enumerate(self.sides):
            target = None if targets_units is None else np.asarray(targets_units[DOF * i: DOF * (i + 1)], np.int64)
            if not self.threaded:
                side.asked_at = self.clock.now()
                side.cycle(target)
                continue
            if self._pending[i] is not None and not self._pending[i].done():
                continue  # previous exchange still on the wire: skip, the aging stamp shows it
            side.asked_at = self.clock.now()
            self._pending[i] = self._executors[i].submit(side.cycle, target)

    def finish_cycle(self, wait_s: float = 0.0) -> HandsReading:
        """Collect the exchange started last tick, waiting at most wait_s for it."""
        deadline = self.clock.now() + wait_s
        for i, future in enumerate(self._pending):
            if future is None:
                continue
            try:
                future.result(timeout=max(0.0, deadline - self.clock.now()))
                self._pending[i] = None
            except FutureTimeout:
                self.sides[i].stats.late_cycles += 1
        faults = []
        for side in self.sides:
            if side.link_lost is not None:
                faults.append(f"{side.side} hand link lost: {side.link_lost}")
            elif side.device_fault is not None:
                faults.append(f"{side.side} hand fault: {side.device_fault}")
            if side.reading_fault is not None:
                faults.append(f"{side.side} hand {side.reading_fault}")
        angles = np.concatenate([s.angles for s in self.sides])
        now = self.clock.now()
        return HandsReading(
            angles=angles,
            forces=np.concatenate([s.forces for s in self.sides]),
            errors=np.concatenate([s.errors for s in self.sides]),
            stamps=np.array([s.stamp for s in self.sides]),
            ages=np.array([s.age(now) for s in self.sides]),
            rad=self.rad_from_units(angles),
            faults=faults,
            every_n_ticks=self.every_n_ticks,
        )

    def command_rates(self, window_s: float) -> dict[str, float]:
        now = self.clock.now()
        return {side.side: side.command_rate(now, window_s) for side in self.sides}

    def stats(self) -> dict[str, dict]:
        out = {}
        for side in self.sides:
            entry = vars(side.stats).copy()
            bus_stats = getattr(side.bus, "stats", None)
            if bus_stats is not None and hasattr(bus_stats, "retries"):
                entry["bus_retries"] = int(bus_stats.retries)
                entry["bus_failures"] = {k: int(v) for k, v in getattr(bus_stats, "failures", {}).items()}
            out[side.side] = entry
        return out

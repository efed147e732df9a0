"""Clocks for the control loop: the real monotonic clock and a fake one tests drive by hand.

The loop only ever asks `now()` and `sleep_until(deadline)` (absolute time, never a relative sleep after compute),
so a fake clock makes every timing decision deterministic in tests.
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float: ...

    def sleep_until(self, deadline: float) -> None: ...


class MonotonicClock:
    """time.monotonic with a sleep that wakes close to an absolute deadline.

    time.sleep overshoots by tens to hundreds of microseconds; `spin_s` busy-waits the last stretch before the
    deadline for tighter wake-ups (costs CPU; 0 disables). With `yield_gil` the spin calls sleep(0), releasing
    the GIL on each turn (kinder to I/O threads, a little less precise).
    """

    def __init__(self, spin_s: float = 0.0, yield_gil: bool = False):
        self.spin_s = spin_s
        self.yield_gil = yield_gil

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, deadline: float) -> None:
        remaining = deadline - time.monotonic()
        if remaining > self.spin_s:
            time.sleep(remaining - self.spin_s)
        if self.yield_gil:
            # sleep(0) drops the GIL on every turn, so hand I/O threads keep running while this one spins
            while time.monotonic() < deadline:
                time.sleep(0)
        else:
            while time.monotonic() < deadline:
                pass


class FakeClock:
    """Time moves only when told: `advance(dt)` or `sleep_until(deadline)` (which jumps there)."""

    def __init__(self, start: float = 1000.0):
        self.t = float(start)
        self.sleeps: list[float] = []

    def now(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.t += dt

    def sleep_until(self, deadline: float) -> None:
        self.sleeps.append(deadline)
        self.t = max(self.t, deadline)

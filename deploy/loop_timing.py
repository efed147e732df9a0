"""The control loop's timing record: lateness, period and compute per tick, overruns with a threshold."""

from __future__ import annotations

import math
from collections import deque

import numpy as np


def stats_ms(values, absolute: bool = False, minus: float = 0.0) -> dict:
    if not len(values):
        return {"p50": None, "p99": None, "max": None}
    arr = np.asarray(values) - minus
    arr = np.abs(arr) if absolute else arr
    return {k: float(v) * 1e3 for k, v in
            (("p50", np.percentile(arr, 50)), ("p99", np.percentile(arr, 99)), ("max", arr.max()))}


class LoopTiming:
    """Per-tick timing, and overruns: a tick that finished after the next deadline. More than `max_overruns`
    overruns within `window_s`, or a single one that ends more than `max_stall_s` after its deadline (the process
    stalled), is a fault (the caller decides when it matters)."""

    def __init__(self, dt: float, max_overruns: int | None, window_s: float, max_stall_s: float | None = None):
        self.dt = dt
        self.max_overruns = max_overruns
        self.window_s = window_s
        self.max_stall_s = max_stall_s
        self._stall: float | None = None  # how far past its deadline the latest overrun ended
        self.lateness: list[float] = []
        self.period: list[float] = []
        self.compute: list[float] = []
        self.overruns = 0
        self.missed_deadlines = 0
        self._recent: deque[float] = deque()
        self._previous_wake: float | None = None

    def record(self, wake: float, deadline: float, done: float) -> None:
        self.lateness.append(wake - deadline)
        self.compute.append(done - wake)
        if self._previous_wake is not None:
            self.period.append(wake - self._previous_wake)
        self._previous_wake = wake

    def overrun(self, done: float, next_deadline: float) -> int:
        """Count an overrun; returns how many deadlines were skipped."""
        skipped = math.ceil((done - next_deadline) / self.dt)
        self._stall = done - next_deadline
        self.overruns += 1
        self.missed_deadlines += skipped
        self._recent.append(done)
        while self._recent and self._recent[0] < done - self.window_s:
            self._recent.popleft()
        return skipped

    def overrun_fault(self) -> str | None:
        if self.max_stall_s is not None and self._stall is not None and self._stall > self.max_stall_s:
            return (f"loop stalled {self._stall * 1e3:.0f} ms past its deadline (limit {self.max_stall_s * 1e3:.1f} ms "
                    f"({self.max_stall_s / self.dt:g} periods))")
        if self.max_overruns is None or len(self._recent) <= self.max_overruns:
            return None
        return f"loop overran {len(self._recent)} deadlines within {self.window_s:g} s (limit {self.max_overruns})"

    def recent(self, seconds: float) -> dict:
        """Lateness and period over the last `seconds`, for the live status."""
        n = max(1, int(seconds / self.dt))
        return {"lateness_ms": stats_ms(self.lateness[-n:]), "period_ms": stats_ms(self.period[-n:])}

    def summary(self) -> dict:
        return {
            "overruns": self.overruns,
            "missed_deadlines": self.missed_deadlines,
            "lateness_ms": stats_ms(self.lateness),
            "period_error_ms": stats_ms(self.period, absolute=True, minus=self.dt),
            "compute_ms": stats_ms(self.compute),
        }

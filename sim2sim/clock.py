"""The runtime's clock in sim2sim: simulation time, where sleeping means stepping the world.

deploy.loop.Runtime only calls `now()` and `sleep_until(deadline)` (deploy.clock.Clock), so handing it this
clock runs the unchanged control loop against the simulated robot as fast as the CPU allows. The clock also
measures, in wall time, how long each control tick took (everything between two sleeps: observation, ONNX,
hand bytes, safety) and how long the physics took, for the report's loop timing.
"""

from __future__ import annotations

import time

from sim2sim.world import SimWorld


class SimClock:
    def __init__(self, world: SimWorld):
        self.world = world
        self.tick_wall_s: list[float] = []  # wall time of each control tick (between sleeps)
        self.physics_wall_s = 0.0
        self._awake_since = time.perf_counter()

    def mark_awake(self) -> None:
        """The loop starts now: the first tick's wall time is counted from here."""
        self._awake_since = time.perf_counter()

    def now(self) -> float:
        return self.world.t

    def sleep_until(self, deadline: float) -> None:
        start = time.perf_counter()
        self.tick_wall_s.append(start - self._awake_since)
        self.world.advance_to(deadline)
        self._awake_since = time.perf_counter()
        self.physics_wall_s += self._awake_since - start

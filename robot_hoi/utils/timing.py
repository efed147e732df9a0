"""Optional wall-time split of the training loop (bench/train_throughput.py reads it).

The env and the runner hold a `timers` attribute that is `OFF` by default: every call on it is an empty method,
so the step path pays nothing measurable. Set a `Timers` to measure:

    timers = Timers()
    env.timers = runner.timers = timers
    ...
    timers.seconds  # {"physics": 1.2, "resets": 0.1, "policy": 0.4, ...}

Two ways to attribute time, both summed into `seconds` by name:
- `lap(name)`: the time since the previous `start()`/`lap()` goes to `name` (a step split into consecutive
  stages without re-indenting it);
- `with section(name):` the time inside the block.
On a GPU the work is asynchronous: pass `sync` (e.g. torch.cuda.synchronize) to wait for it at every boundary.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable


class Timers:
    def __init__(self, sync: Callable[[], None] | None = None) -> None:
        self.sync = sync
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def _now(self) -> float:
        if self.sync is not None:
            self.sync()
        return time.perf_counter()

    def start(self) -> None:
        """Start the lap clock (what happened since is attributed by the next lap)."""
        self._last = self._now()

    def lap(self, name: str) -> None:
        """Add the time since the last start()/lap() to `name`."""
        now = self._now()
        self.seconds[name] = self.seconds.get(name, 0.0) + now - self._last
        self._last = now

    @contextlib.contextmanager
    def section(self, name: str):
        start = self._now()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + self._now() - start

    def reset(self) -> None:
        self.seconds.clear()
        self._last = time.perf_counter()


class _Off:
    """Timing switched off: every call does nothing."""

    _NULL = contextlib.nullcontext()

    def start(self) -> None:
        pass

    def lap(self, name: str) -> None:
        pass

    def section(self, name: str) -> contextlib.nullcontext:
        return self._NULL


OFF = _Off()

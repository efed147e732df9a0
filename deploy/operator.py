"""Operator input for the runtime: confirm (stiffen, start the policy), stop, e-stop.

`poll()` returns the events that arrived since the last call: "start" (confirm the gate the runtime waits at:
ZERO_TORQUE -> stiffen and ramp to the default pose, HOLD -> start the policy; ignored elsewhere), "stop" (end
the run through DAMP) or "estop" (DAMP now). Implementations: `OperatorInput` (no operator: dry runs with
SafetyConfig.auto_start_after_s), `KeyboardOperator` (a thread reading lines on stdin: Enter or "s" = start,
"q" = stop, "x"/"e" = e-stop), `ScriptedOperator` (events at given clock times, for tests). The wireless remote
(deploy.remote) arrives with the body state and is read by the runtime itself; signals come through
deploy.signals.
"""

from __future__ import annotations

import sys
import threading
from collections import deque

from deploy.clock import Clock

EVENTS = ("start", "stop", "estop")


class OperatorInput:
    def poll(self) -> list[str]:
        return []

    def close(self) -> None:
        return None


class ScriptedOperator(OperatorInput):
    def __init__(self, clock: Clock, script: list[tuple[float, str]]):
        self.clock = clock
        self._script = deque(sorted(script))

    def poll(self) -> list[str]:
        out = []
        while self._script and self._script[0][0] <= self.clock.now():
            out.append(self._script.popleft()[1])
        return out


class KeyboardOperator(OperatorInput):
    KEYS = {"": "start", "s": "start", "q": "stop", "x": "estop", "e": "estop"}

    def __init__(self, stream=None):
        self._stream = stream or sys.stdin
        self._events: deque[str] = deque()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._read, name="operator-keyboard", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        for line in self._stream:
            event = self.KEYS.get(line.strip().lower())
            if event is not None:
                with self._lock:
                    self._events.append(event)

    def poll(self) -> list[str]:
        with self._lock:
            out = list(self._events)
            self._events.clear()
        return out

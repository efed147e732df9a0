"""SIGINT, SIGTERM and SIGHUP through one path: the runtime damps, writes its summary and exits with a code that
names the signal (deploy.outcome). A dropped SSH session (SIGHUP), `systemctl stop` / `docker stop` (SIGTERM) and
Ctrl-C (SIGINT) all end the same way; a second signal aborts after one damping command.

Before the runtime exists (opening ports, loading the policy) nothing has been commanded, so a signal interrupts
the setup (`Interrupted`) and everything opened so far is closed. After the run, while hands close and the summary
is written, further signals are noted and ignored: the robot is already damped.
"""

from __future__ import annotations

import signal

HANDLED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Interrupted(Exception):
    """A signal arrived before the runtime started (nothing was commanded)."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(f"{signal.Signals(signum).name} during setup")


class SignalRouter:
    """Context manager: while `target` (a Runtime) is set, signals go to target.request_signal."""

    def __init__(self) -> None:
        self.target = None
        self.finished = False
        self.received: list[str] = []
        self._previous: dict[int, object] = {}

    def __enter__(self) -> SignalRouter:
        for signum in HANDLED:
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc_info) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum: int, frame) -> None:
        self.received.append(signal.Signals(signum).name)
        if self.target is not None:
            self.target.request_signal(signum)
        elif not self.finished:
            raise Interrupted(signum)

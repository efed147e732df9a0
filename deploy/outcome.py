"""Why a run ended, and the exit code that says so (the table in deploy/README.md "Exit codes").

0 only when the policy ran and then stopped as planned: its --duration ran out, or the operator stopped it (q,
remote SELECT, one Ctrl-C; sim2sim's monitor stops it at the end of the clip the same way). Everything else
names its cause in the code as well as in summary.json.
"""

from __future__ import annotations

import enum
import signal
import threading


class Outcome(enum.Enum):
    COMPLETED = (0, "the policy ran and stopped as planned (duration ran out, operator stop)")
    FAULT = (1, "a safety fault damped the robot")
    USAGE = (2, "bad command line, policy file, config or port; nothing was commanded")
    NOT_STARTED = (3, "the policy never ran: inputs never became usable, or stopped before the policy started")
    REFUSED = (4, "refused before stiffening: wrong robot (mode_machine), another rt/lowcmd publisher, "
                  "motor errors or over-temperature")
    ESTOP = (5, "operator e-stop (x on the keyboard, remote B)")
    CRASHED = (70, "internal error (traceback on stderr); one damping command was sent on the way out")
    SIGHUP = (128 + signal.SIGHUP, "SIGHUP (terminal or SSH session gone): damped, summary written")
    SIGINT = (128 + signal.SIGINT, "Ctrl-C twice: aborted after one damping command")
    SIGTERM = (128 + signal.SIGTERM, "SIGTERM (systemctl/docker stop, kill): damped, summary written")

    @property
    def code(self) -> int:
        return self.value[0]

    @property
    def meaning(self) -> str:
        return self.value[1]


class StopRequests:
    """Stop requests from the loop, another thread or a signal handler. The first one is the reason. Further
    stops and e-stops (keyboard, remote) never shorten the damping; only a second signal after a first one (Ctrl-C
    twice) aborts after one damping command. Kinds: operator, duration, estop, signal. SIGINT is the operator's
    stop (Ctrl-C); SIGTERM and SIGHUP name themselves in the exit code."""

    def __init__(self) -> None:
        self.first: tuple[str, str] | None = None  # (kind, reason)
        self.signal_name: str | None = None
        self._signals = 0
        self._abort = threading.Event()

    def request(self, reason: str, kind: str = "operator") -> None:
        if self.first is None:
            self.first = (kind, reason)

    def signal(self, signum: int) -> None:
        self._signals += 1
        if self._signals > 1:
            self._abort.set()
            return
        self.signal_name = signal.Signals(signum).name
        self.request(self.signal_name, "operator" if signum == signal.SIGINT else "signal")

    @property
    def reason(self) -> str | None:
        return self.first[1] if self.first else None

    @property
    def aborted(self) -> bool:
        return self._abort.is_set()

    @property
    def estop(self) -> bool:
        return bool(self.first and self.first[0] == "estop")


def classify(*, refused: bool, faults: bool, stops: StopRequests, policy_ran: bool) -> Outcome:
    """The one outcome of a finished run, most serious cause first."""
    name = stops.signal_name
    if refused:
        return Outcome.REFUSED
    if faults:
        return Outcome.FAULT
    if name in ("SIGTERM", "SIGHUP") or (stops.aborted and name is not None):
        return Outcome[name]
    if stops.estop:
        return Outcome.ESTOP
    return Outcome.COMPLETED if policy_ran else Outcome.NOT_STARTED

"""The operator's live view while the runtime runs: phase, loop timing, hand command rates, faults, and what the
operator is asked to do (e.g. "HOLD reached: press Enter ... to start the policy").

On a terminal a rich status line is redrawn in place (at most `refresh_hz` times a second, from the loop thread
after a tick's commands are out); otherwise plain lines are printed when the phase, prompt or faults change and
every `plain_every_s` seconds (journald, a log file, a CI job). Both write to stderr: stdout keeps the summary.
"""

from __future__ import annotations

import sys
from typing import TextIO

from rich.console import Console
from rich.live import Live
from rich.text import Text


def status_text(runtime) -> str:
    """One line: 'POLICY 12.3 s | loop 30 Hz, late p99 0.8 ms, overruns 0 | hands L 30.0 R 30.0 Hz | faults none'."""
    now = runtime.clock.now()
    recent = runtime.timing.recent(1.0)["lateness_ms"]
    late = "n/a" if recent["p99"] is None else f"{recent['p99']:.1f} ms"
    rates = runtime.hands.command_rates(1.0)
    hands = " ".join(f"{side[0].upper()} {rate:.1f}" for side, rate in rates.items())
    faults = "; ".join(runtime.fault_reasons) or "none"
    refused = f" | start refused: {runtime.start_refusal}" if runtime.start_refusal else ""
    return (f"{runtime.phase.name} {now - runtime.phase_since:.1f} s | loop {1 / runtime.dt:.0f} Hz, late p99 {late}, "
            f"overruns {runtime.timing.overruns} | hands {hands} Hz | faults {faults}{refused}")


class NullStatus:
    def update(self, runtime) -> None:
        return None

    def close(self) -> None:
        return None


class PlainStatus(NullStatus):
    def __init__(self, stream: TextIO | None = None, plain_every_s: float = 5.0):
        self.stream = stream or sys.stderr
        self.plain_every_s = plain_every_s
        self._key = None
        self._last = float("-inf")

    def update(self, runtime) -> None:
        now = runtime.clock.now()
        key = (runtime.phase, runtime.prompt, len(runtime.fault_reasons), runtime.start_refusal)
        if key == self._key and now - self._last < self.plain_every_s:
            return
        if runtime.prompt and key != self._key:
            print(f">>> {runtime.prompt}", file=self.stream, flush=True)
        self._key, self._last = key, now
        print(status_text(runtime), file=self.stream, flush=True)


class RichStatus(NullStatus):
    def __init__(self, stream: TextIO | None = None, refresh_hz: float = 4.0):
        self.console = Console(file=stream or sys.stderr)
        self.live = Live(console=self.console, auto_refresh=False, transient=True)
        self.live.start()
        self.period = 1.0 / refresh_hz
        self._last = float("-inf")
        self._phase = None

    def update(self, runtime) -> None:
        now = runtime.clock.now()
        if runtime.phase != self._phase:  # phase changes stay on screen above the live line
            self._phase = runtime.phase
            self.live.console.print(f"[bold]{runtime.phase.name}[/bold]")
        elif now - self._last < self.period:
            return
        self._last = now
        text = Text(status_text(runtime), style="red" if runtime.fault_reasons else "")
        if runtime.prompt:
            text.append(f"\n>>> {runtime.prompt}", style="bold yellow")
        self.live.update(text, refresh=True)

    def close(self) -> None:
        try:
            self.live.stop()
        except Exception:  # the terminal is gone (EIO after SIGHUP): nothing left to tidy on it
            pass


def make_status_view(mode: str = "auto", stream: TextIO | None = None):
    """'auto': rich on a terminal, plain lines otherwise; 'plain'; 'off'."""
    stream = stream or sys.stderr
    if mode == "off":
        return NullStatus()
    if mode == "auto" and stream.isatty():
        return RichStatus(stream)
    return PlainStatus(stream)

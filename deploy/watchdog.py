"""Watchdogs that do not depend on the control loop: when the loop's heartbeat stops while it commands the robot,
they send damping themselves.

The loop beats once a tick, after its commands are out (`beat(commanding)`; commanding: anything has been sent to
the robot), reads `check()` (the reason, once the watchdog fired: the loop faults to DAMP and never stiffens again)
and says goodbye with `end(clean=True)` when it stopped on purpose.

    ThreadWatchdog   a thread in the runtime's process, sending damping through the runtime's own body (the
                     simulated body of a dry run). It needs the interpreter: it covers a loop stuck in Python or
                     in a call that releases the GIL, not a dead process.
    ProcessWatchdog  a child process (`python -m deploy.watchdog`) with its own DDS participant, for the real body.
                     It fires when the heartbeat stops for `timeout_s`, or when the pipe from the runtime closes
                     without a goodbye (its process died: SIGKILL, OOM kill, native crash), and then publishes
                     damping LowCmds (kp 0, kd damp_kd) on rt/lowcmd for `damp_s`. Its writer is created only when
                     it fires, so until then it is not "another rt/lowcmd publisher" to the identity check. It
                     ignores SIGINT, SIGTERM and SIGHUP (those reach the runtime, which damps) and lives in its
                     own session, so a closing terminal does not take it down.

Pipe protocol (runtime -> child stdin, one byte a tick): b"c" commanding, b"w" nothing commanded yet (silence is
not acted on), b"q" goodbye. Child -> runtime (stdout): b"R" ready, b"F" fired.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from deploy.body.unitree_dds import LOWCMD_TOPIC, dds_participant, idl_types, lowcmd_to_idl
from deploy.body.unitree_lowlevel import make_lowcmd
from deploy.errors import DeployError


def _reason(silence_s: float, timeout_s: float, who: str) -> str:
    return (f"watchdog: loop heartbeat stopped for {silence_s * 1e3:.0f} ms (limit {timeout_s * 1e3:.0f} ms); "
            f"{who} damped the robot")


class NullWatchdog:
    description = "off"

    def start(self, send_damping: Callable[[], None]) -> None:
        return None

    def beat(self, commanding: bool) -> None:
        return None

    def check(self) -> str | None:
        return None

    def end(self, clean: bool) -> None:
        return None

    def close(self) -> None:
        return None


class ThreadWatchdog(NullWatchdog):
    def __init__(self, timeout_s: float):
        self.timeout_s = timeout_s
        self.description = f"thread, {timeout_s * 1e3:.0f} ms"
        self.fired: str | None = None
        self._last = time.monotonic()
        self._commanding = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._send_damping: Callable[[], None] | None = None

    def start(self, send_damping: Callable[[], None]) -> None:
        self._send_damping = send_damping
        self._last = time.monotonic()
        self._stop.clear()
        self._thread = threading.Thread(target=self._watch, name="loop-watchdog", daemon=True)
        self._thread.start()

    def beat(self, commanding: bool) -> None:
        self._last = time.monotonic()
        self._commanding = commanding

    def check(self) -> str | None:
        return self.fired

    def _watch(self) -> None:
        poll = self.timeout_s / 4
        while not self._stop.wait(poll):
            silence = time.monotonic() - self._last
            if self._commanding and silence > self.timeout_s:
                reason = _reason(silence, self.timeout_s, "the watchdog thread")
                try:
                    self._send_damping()
                except Exception as exc:  # e.g. the body link is down too: the loop's fault path still runs
                    reason = f"{reason} (its damping command failed: {exc})"
                self.fired = reason
                return

    def end(self, clean: bool) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(1.0)

    def close(self) -> None:
        self.end(clean=True)


class ProcessWatchdog(NullWatchdog):
    """Starts the child and waits for it to be ready (its DDS participant up); a child that does not come up is a
    DeployError: a real body is not commanded without its watchdog."""

    def __init__(self, *, timeout_s: float, damp_s: float, period_s: float, damp_kd: float, num_joints: int,
                 domain_id: int, interface: str | None, mode_machine: int | None, start_timeout_s: float = 30.0):
        self.timeout_s = timeout_s
        self.description = f"process, {timeout_s * 1e3:.0f} ms"
        self.fired: str | None = None
        self._said_goodbye = False
        config = {"timeout_s": timeout_s, "damp_s": damp_s, "period_s": period_s, "damp_kd": damp_kd,
                  "num_joints": num_joints, "domain_id": domain_id, "interface": interface,
                  "mode_machine": mode_machine or 0}
        env = dict(os.environ)
        package_parent = str(Path(__file__).resolve().parents[1])  # `deploy` importable from any working directory
        env["PYTHONPATH"] = os.pathsep.join(p for p in (package_parent, env.get("PYTHONPATH")) if p)
        self._proc = subprocess.Popen([sys.executable, "-m", "deploy.watchdog", json.dumps(config)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env,
                                      start_new_session=True)
        self._in = self._proc.stdin.fileno()
        self._out = self._proc.stdout.fileno()
        ready, _, _ = select.select([self._out], [], [], start_timeout_s)
        first = os.read(self._out, 1) if ready else b""
        if first != b"R":
            self._proc.kill()
            self._proc.wait()
            raise DeployError(f"the watchdog process did not come up within {start_timeout_s:g} s "
                              f"(exit code {self._proc.returncode}; see stderr above)")
        os.set_blocking(self._in, False)
        os.set_blocking(self._out, False)

    def beat(self, commanding: bool) -> None:
        try:
            os.write(self._in, b"c" if commanding else b"w")
        except OSError:  # full pipe (child busy firing) or child gone: nothing the loop can do about it here
            pass

    def check(self) -> str | None:
        """The reason once it fired; a watchdog process that died is a fault too (nothing guards the robot)."""
        if self.fired is None:
            try:
                data = os.read(self._out, 64)
            except (BlockingIOError, OSError):
                data = b""
            if b"F" in data:
                self.fired = _reason(self.timeout_s, self.timeout_s, "the watchdog process")
            elif not self._said_goodbye and self._proc.poll() is not None:
                self.fired = f"watchdog process exited (code {self._proc.returncode}): the robot has no watchdog"
        return self.fired

    def end(self, clean: bool) -> None:
        """clean: the runtime damped and stopped on purpose; the child exits without firing. Otherwise the child
        stays armed: when this process exits (or stays silent) it damps."""
        if clean and not self._said_goodbye:
            self._said_goodbye = True
            try:
                os.set_blocking(self._in, True)
                os.write(self._in, b"q")
            except OSError:
                pass

    def close(self) -> None:
        for stream in (self._proc.stdin, self._proc.stdout):
            try:
                stream.close()
            except OSError:
                pass
        if self._said_goodbye:
            try:
                self._proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()


# ---------------------------------------------------------------------------------------------- the child process
class _DdsDamper:
    """The child's side: a DDS participant from the start, an rt/lowcmd writer only once it fires."""

    def __init__(self, config: dict):
        self.config = config
        self.T = idl_types()
        self.participant = dds_participant(config["domain_id"], config["interface"])
        n = config["num_joints"]
        zeros = np.zeros(n)
        frame = make_lowcmd(zeros, zeros, zeros, np.full(n, config["damp_kd"]), zeros,
                            mode_machine=config["mode_machine"])
        self.message = lowcmd_to_idl(frame)

    def fire(self, notify: Callable[[], None]) -> None:
        """Publish damping every period for damp_s, and on until the robot's reader has matched (a volatile
        sample published before discovery is lost), at most 2 s longer."""
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        writer = DataWriter(self.participant, Topic(self.participant, LOWCMD_TOPIC, self.T.LowCmd_))
        start = time.monotonic()
        matched_since = None
        notified = False
        while True:
            writer.write(self.message)
            if not notified:
                notify()
                notified = True
            now = time.monotonic()
            if matched_since is None and writer.get_publication_matched_status().current_count > 0:
                matched_since = now
            done = now - start >= self.config["damp_s"]
            delivered = matched_since is not None and now - matched_since >= 0.1
            if done and (delivered or now - start >= self.config["damp_s"] + 2.0):
                return
            time.sleep(self.config["period_s"])


def _say(byte: bytes) -> None:
    try:
        os.write(sys.stdout.fileno(), byte)
    except OSError:  # the runtime is gone: nobody to tell
        pass


def main(argv: list[str] | None = None) -> int:
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_IGN)
    config = json.loads((argv if argv is not None else sys.argv[1:])[0])
    damper = _DdsDamper(config)
    _say(b"R")
    fd = sys.stdin.fileno()
    state, last = b"w", time.monotonic()
    timeout = config["timeout_s"]
    while True:
        wait = max(0.0, last + timeout - time.monotonic()) if state == b"c" else None
        readable, _, _ = select.select([fd], [], [], wait)
        if readable:
            data = os.read(fd, 4096)
            if not data:  # the runtime's process is gone without a goodbye
                if state == b"c":
                    damper.fire(lambda: None)
                return 0
            state, last = data[-1:], time.monotonic()
            if state == b"q":
                return 0
        elif state == b"c":  # the heartbeat stopped: the loop is stuck
            damper.fire(lambda: _say(b"F"))
            return 0


if __name__ == "__main__":
    sys.exit(main())

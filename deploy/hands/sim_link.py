"""Plumbing for the simulated hands: a pseudo-terminal that behaves like a USB-RS485 adapter (it can be
unplugged and plugged back under the same path) and a wire clock that paces replies at the line rate.

A pty moves bytes instantly, so without pacing a simulated hand would answer faster than any real RS485 or
CAN link could. `LineClock` books each request + reply on a virtual wire (bytes x 10 bits / baud for 8N1 serial,
frame bits / bitrate for CAN) and the device sends its reply only when the wire would have delivered it.
"""

from __future__ import annotations

import os
import select
import shutil
import tempfile
import threading
import time
import tty
from pathlib import Path

SPIN_S = 0.0003  # the last stretch before a deadline is spun, not slept, so replies are not late by ~60 us


def sleep_until(deadline: float) -> None:
    """Sleep until time.monotonic() >= deadline, busy-waiting the final SPIN_S (sleep(0) would yield the CPU
    to other processes for tens of microseconds). The host thread is blocked on I/O meanwhile, so holding
    the GIL for those few hundred microseconds costs it nothing."""
    remaining = deadline - time.monotonic()
    if remaining > SPIN_S:
        time.sleep(remaining - SPIN_S)
    while time.monotonic() < deadline:
        pass


class LineClock:
    """A half-duplex wire shared by everyone who books on it (one per pty, one per CAN channel)."""

    def __init__(self) -> None:
        self._free_at = 0.0
        self._lock = threading.Lock()

    def book(self, earliest_start: float, duration_s: float) -> float:
        """Reserve the wire for `duration_s` from `earliest_start` (or when it frees up); returns the end time."""
        with self._lock:
            start = max(earliest_start, self._free_at)
            self._free_at = start + duration_s
            return self._free_at

    def busy_until(self, t: float) -> None:
        """A transmission really ended at `t` (later than booked): nothing else can finish on the wire before
        t plus its own duration, so a late reply is never followed by an impossibly fast one."""
        with self._lock:
            self._free_at = max(self._free_at, t)


class PtyLink:
    """Device end of a pseudo-terminal pair, reachable by the host under a stable symlink path.

    `unplug()` closes both ends and removes the path, like pulling a USB adapter (the host's open port starts
    failing with I/O errors); `plug()` creates a fresh pty under the same path.
    """

    def __init__(self, name: str):
        self._dir = Path(tempfile.mkdtemp(prefix="inspire-sim-"))
        self.path = str(self._dir / name)
        self._master: int | None = None
        self._slave: int | None = None
        self._lock = threading.Lock()  # the device thread reads while a test thread may unplug
        self.plug()

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def plug(self) -> None:
        with self._lock:
            self._plug()

    def _plug(self) -> None:
        if self._master is not None:
            return
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo or newline translation before the host configures the port
        os.set_blocking(master, False)
        self._master, self._slave = master, slave  # keep the slave open: reads on the master never see EIO
        tmp = self.path + ".new"
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.path)

    def unplug(self) -> None:
        with self._lock:
            self._unplug()

    def _unplug(self) -> None:
        if self._master is None:
            return
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master = self._slave = None

    def read(self, timeout: float) -> bytes:
        """Bytes the host wrote (b'' on timeout or while unplugged)."""
        with self._lock:
            fd = self._master
            if fd is not None:
                try:
                    ready, _, _ = select.select([fd], [], [], timeout)
                    return os.read(fd, 4096) if ready else b""
                except OSError:
                    return b""
        time.sleep(timeout)
        return b""

    def write(self, data: bytes) -> None:
        with self._lock:
            fd = self._master
            if fd is None or not data:
                return
            view = memoryview(data)
            while view:
                try:
                    written = os.write(fd, view)
                except BlockingIOError:
                    select.select([], [fd], [], 0.01)
                    continue
                except OSError:
                    return
                view = view[written:]

    def close(self) -> None:
        self.unplug()
        shutil.rmtree(self._dir, ignore_errors=True)

"""Simulation plumbing: the wire clock and the unpluggable pty."""

from __future__ import annotations

import os
import time

import serial

from deploy.hands.sim_link import LineClock, PtyLink, sleep_until


def test_line_clock_serialises_bookings():
    clock = LineClock()
    assert clock.book(10.0, 1.0) == 11.0
    assert clock.book(10.5, 1.0) == 12.0  # the wire was still busy: queued behind the first booking
    assert clock.book(20.0, 0.5) == 20.5  # idle wire: starts when asked
    clock.busy_until(21.0)  # that reply really went out at 21.0
    assert clock.book(20.6, 0.5) == 21.5


def test_sleep_until_is_not_early():
    deadline = time.monotonic() + 0.002
    sleep_until(deadline)
    assert time.monotonic() >= deadline


def test_pty_link_moves_bytes_and_survives_unplug_plug():
    link = PtyLink("hand")
    try:
        host = serial.Serial(link.path, 115200, timeout=0.5)
        host.write(b"\xeb\x90ping")
        assert link.read(0.5) == b"\xeb\x90ping"
        link.write(b"\x90\xebpong")
        assert host.read(6) == b"\x90\xebpong"
        link.unplug()
        assert not os.path.exists(link.path) and not link.plugged
        assert link.read(0.01) == b""
        link.plug()
        assert link.plugged and os.path.exists(link.path)
        host.close()
        host = serial.Serial(link.path, 115200, timeout=0.5)  # same path, fresh pty
        link.write(b"again")
        assert host.read(5) == b"again"
        host.close()
    finally:
        link.close()
    assert not os.path.exists(link.path)

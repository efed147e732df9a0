"""Simulated Inspire hands that speak the real bytes, for tests, benchmarks and sim2sim without hardware.

    sim = start_simulated_hand("serial", "right")          # vendor EB 90 frames on a pty
    bus = make_hand_bus("serial", "right", **sim.bus_kwargs())
    sim.model.place_object([500] * 6); sim.drop_next(2); sim.disconnect(); sim.reconnect(); sim.stop()

Transports: "serial" (vendor frames on a pseudo-terminal), "modbus" (Modbus RTU on a pseudo-terminal, framed
and CRC-checked by pymodbus), "can" (python-can `virtual` channel, 29-bit ids). Each device runs one
background thread and paces its replies at the configured line rate (see sim_link), so timing measured
against it is honest; pass pace=False to answer as fast as possible.

Fault injection applies to the next replies in the order it was asked for: drop_next, corrupt_checksum_next,
garble_next, partial_next, noise_before_next (noise then a good reply: the host must resync) and, for CAN,
error_frame_next. On CAN every reply frame counts (a 12-byte read is 2 replies); there is no software
checksum there, so corrupt_checksum_next sends an error frame in place of the reply (what a CRC error looks
like to the host), garble_next a reply of the wrong length and partial_next one cut short.
refuse_writes_next answers the next writes with a refusal; set_error_bits sets ERROR bits in the model;
override_reading makes a register report a value of your choice (out of range, too);
disconnect()/reconnect() unplug and replug the hand.
"""

from __future__ import annotations

import logging
import random
import threading
import time
from collections import Counter, deque

from deploy.errors import DeployError
from deploy.hand_units import HAND_SIDES
from deploy.hands.finger_model import FingerModel
from deploy.hands.sim_link import LineClock, sleep_until
from deploy.hands.sim_registers import DeviceRegisters, WriteRecord

log = logging.getLogger("deploy.hands.simulated")

POLL_S = 0.02  # how long the device thread waits for input before checking for stop()


class SimulatedHand:
    """Base of the simulated devices: register file, model, fault queue, counters, thread, pacing."""

    transport = ""

    def __init__(
        self,
        side: str,
        hand_id: int = 1,
        *,
        model: FingerModel | None = None,
        pace: bool = True,
        turnaround_s: float = 0.0,
        seed: int = 0,
        can_layout: bool = False,
    ):
        if side not in HAND_SIDES:
            raise DeployError(f"hand side must be one of {HAND_SIDES}, got {side!r}")
        self.side = side
        self.model = model or FingerModel()
        self.registers = DeviceRegisters(self.model, hand_id, can=can_layout)
        self.pace = pace
        self.turnaround_s = float(turnaround_s)
        self.clock = LineClock()
        self.requests: Counter = Counter()  # (op, first register name) -> requests that reached this hand
        self.faults_applied: Counter = Counter()
        self.replies_sent = 0
        self.wire_bits = 0  # line bits of every request this hand answered and of its replies
        self.late_s = 0.0  # total time replies left after the paced wire deadline (simulator's own lag)
        self._faults: deque[str] = deque()
        self._refusals = 0  # writes still to be refused (NACK / Modbus exception)
        self._faults_lock = threading.Lock()
        self._rng = random.Random(seed)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ----------------------------------------------------------------- lifecycle
    def start(self) -> SimulatedHand:
        self._thread = threading.Thread(
            target=self._run, name=f"sim-{self.transport}-{self.side}", daemon=True
        )
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._release()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._serve_once(POLL_S)
            except Exception:  # a device bug must show up in the test log, not kill the thread silently
                log.exception("simulated %s hand (%s) failed while serving", self.transport, self.side)

    # ----------------------------------------------------------------- to be provided by each device
    def _serve_once(self, timeout: float) -> None:
        raise NotImplementedError

    def _release(self) -> None:
        """Free the pty / CAN bus."""

    def disconnect(self) -> None:
        """Unplug: the host's link fails (pty) or the hand goes silent (CAN)."""
        raise NotImplementedError

    def reconnect(self) -> None:
        raise NotImplementedError

    def bus_kwargs(self) -> dict:
        """Keyword arguments for make_hand_bus(self.transport, self.side, **kwargs)."""
        raise NotImplementedError

    @property
    def line_rate(self) -> float:
        """Bits per second of the simulated line (baud rate, or CAN bit rate)."""
        raise NotImplementedError

    # ----------------------------------------------------------------- spying
    @property
    def hand_id(self) -> int:
        return self.registers.hand_id

    @property
    def writes(self) -> list[WriteRecord]:
        """Every register write that reached the device, as element values."""
        return self.registers.writes

    @property
    def total_requests(self) -> int:
        return sum(self.requests.values())

    # ----------------------------------------------------------------- faults
    def set_error_bits(self, bits: int, fingers=None, sticky: bool = False) -> None:
        self.model.set_error_bits(bits, fingers, sticky)

    def override_reading(self, register: str, finger: int, value: int | None) -> None:
        """Report `value` in element `finger` of a live register (e.g. ANGLE_ACT = 4000, a firmware glitch or a
        wrong byte order) until called again with None."""
        if value is None:
            self.registers.overrides.pop((register, finger), None)
        else:
            self.registers.overrides[(register, finger)] = int(value)

    def drop_next(self, n: int = 1) -> None:
        self._queue_fault("drop", n)

    def corrupt_checksum_next(self, n: int = 1) -> None:
        self._queue_fault("checksum", n)

    def garble_next(self, n: int = 1) -> None:
        self._queue_fault("garble", n)

    def partial_next(self, n: int = 1) -> None:
        self._queue_fault("partial", n)

    def noise_before_next(self, n: int = 1) -> None:
        self._queue_fault("noise", n)

    def error_frame_next(self, n: int = 1) -> None:
        if self.transport != "can":
            raise ValueError("error frames exist only on CAN")
        self._queue_fault("error_frame", n)

    def refuse_writes_next(self, n: int = 1) -> None:
        """The hand answers the next n writes but refuses them (vendor ack 0x00, CAN ack 0x00, Modbus
        exception 4); nothing is written."""
        with self._faults_lock:
            self._refusals += int(n)

    def _take_refusal(self) -> bool:
        with self._faults_lock:
            if self._refusals <= 0:
                return False
            self._refusals -= 1
        self.faults_applied["refuse"] += 1
        return True

    def pending_faults(self) -> int:
        with self._faults_lock:
            return len(self._faults)

    def _queue_fault(self, kind: str, n: int) -> None:
        with self._faults_lock:
            self._faults.extend([kind] * int(n))

    def _take_fault(self) -> str | None:
        with self._faults_lock:
            kind = self._faults.popleft() if self._faults else None
        if kind is not None:
            self.faults_applied[kind] += 1
        return kind

    # ----------------------------------------------------------------- pacing and byte faults
    def _wait_for_wire(self, arrival: float, wire_s: float) -> None:
        if self.pace:
            deadline = self.clock.book(arrival, wire_s + self.turnaround_s)
        elif self.turnaround_s:
            deadline = arrival + self.turnaround_s
        else:
            return
        sleep_until(deadline)
        late = time.monotonic() - deadline  # > 0 when this thread was not scheduled in time
        if late > 0:
            self.late_s += late
            self.clock.busy_until(deadline + late)

    def _noise(self, n: int, avoid: bytes) -> bytes:
        """Random bytes without any byte of `avoid`, so noise never contains a frame start by accident."""
        choices = [b for b in range(256) if b not in avoid]
        return bytes(self._rng.choice(choices) for _ in range(n))

    def _apply_byte_fault(self, reply: bytes, fault: str | None, avoid: bytes) -> bytes:
        if fault is None:
            return reply
        if fault == "drop":
            return b""
        if fault == "checksum":
            return reply[:-1] + bytes([reply[-1] ^ 0xFF])
        if fault == "garble":
            return self._noise(len(reply), avoid)
        if fault == "partial":
            return reply[: max(1, len(reply) // 2)]
        if fault == "noise":
            return self._noise(7, avoid) + reply
        raise ValueError(f"fault {fault!r} does not apply to a byte stream")


def start_simulated_hand(transport: str, side: str, hand_id: int = 1, **options) -> SimulatedHand:
    """Start a simulated hand speaking `transport` ("serial", "modbus", "can") and return it.

    Options: model (FingerModel), pace (bool, default True), turnaround_s, seed, baudrate (serial/modbus,
    default 115200), channel and bitrate (CAN; default a fresh virtual channel, 1 Mbit/s).
    """
    if transport == "serial":
        from deploy.hands.sim_serial import SimulatedSerialHand as cls
    elif transport == "modbus":
        from deploy.hands.sim_serial import SimulatedModbusHand as cls
    elif transport == "can":
        from deploy.hands.sim_can import SimulatedCanHand as cls
    else:
        raise DeployError(f"unknown hand transport {transport!r}; use serial, modbus or can")
    return cls(side, hand_id, **options).start()


def wait_until(predicate, timeout: float = 2.0, interval: float = 0.005) -> bool:
    """Poll `predicate` until it is true or `timeout` passes (test helper for the model's motion)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval)
    return bool(predicate())

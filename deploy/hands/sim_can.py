"""Simulated hand on a python-can `virtual` channel, answering Inspire CAN frames.

Hands on the same channel share one wire clock, so two simulated hands on one bus are paced together.
disconnect() takes the hand off the bus (it goes silent, as with a cut cable); reconnect() puts it back.
"""

from __future__ import annotations

import threading
import time
import uuid
import weakref

import can

from deploy.hands import can_frames
from deploy.hands.can_frames import ERROR_FRAME_BITS, RW_READ, frame_bits
from deploy.hands.sim_link import LineClock
from deploy.hands.simulated import SimulatedHand

_CLOCKS: weakref.WeakValueDictionary[str, LineClock] = weakref.WeakValueDictionary()
_CLOCKS_LOCK = threading.Lock()

WRITE_ACK = b"\x01"  # the manual says the ack has DLC 1; its content is not documented (0x01 as on RS485)
WRITE_REFUSED = b"\x00"


def _clock_for(channel: str) -> LineClock:
    with _CLOCKS_LOCK:
        clock = _CLOCKS.get(channel)
        if clock is None:
            clock = LineClock()
            _CLOCKS[channel] = clock
        return clock


class SimulatedCanHand(SimulatedHand):
    transport = "can"

    def __init__(
        self, side: str, hand_id: int = 1, *, channel: str | None = None, bitrate: int = 1_000_000, **options
    ):
        super().__init__(side, hand_id, can_layout=True, **options)
        self.channel = channel or f"inspire-sim-{uuid.uuid4().hex[:8]}"
        self.bitrate = int(bitrate)
        self.clock = _clock_for(self.channel)
        self._bus_lock = threading.Lock()
        self._bus: can.BusABC | None = None
        self.reconnect()

    def bus_kwargs(self) -> dict:
        return {
            "can_channel": self.channel,
            "can_interface": "virtual",
            "hand_id": self.hand_id,
            "can_bitrate": self.bitrate,
        }

    @property
    def line_rate(self) -> float:
        return float(self.bitrate)

    def disconnect(self) -> None:
        with self._bus_lock:
            if self._bus is not None:
                self._bus.shutdown()
                self._bus = None

    def reconnect(self) -> None:
        with self._bus_lock:
            if self._bus is None:
                self._bus = can.Bus(interface="virtual", channel=self.channel, receive_own_messages=False)

    def _release(self) -> None:
        self.disconnect()

    def send_error_frame(self) -> None:
        """Put one error frame on the bus now (e.g. to test that the host counts them)."""
        with self._bus_lock:
            if self._bus is not None:
                self._bus.send(can.Message(is_error_frame=True, is_extended_id=True))

    def _serve_once(self, timeout: float) -> None:
        with self._bus_lock:
            bus = self._bus
        if bus is None:
            time.sleep(timeout)
            return
        try:
            msg = bus.recv(timeout)
        except can.CanOperationError:
            return  # disconnect() closed the bus under us
        if msg is None:
            return
        # When the frame went on the bus (virtual buses stamp it at send); frames queued behind a reply we
        # were pacing are not late, they were already waiting on the wire.
        arrival = time.monotonic() - max(0.0, time.time() - msg.timestamp)
        request = can_frames.parse_request(msg, self.hand_id)
        if request is None:
            return
        rw, address, data = request
        group = self.registers.group_at(address)
        name = group[1].name if group else f"@{address}"
        if rw == RW_READ:
            self.requests[("read", name)] += 1
            reply_data = self.registers.read(address, data[0])
        else:
            self.requests[("write", name)] += 1
            if self._take_refusal():
                reply_data = WRITE_REFUSED
            else:
                self.registers.write(address, data)
                reply_data = WRITE_ACK
        self._reply(bus, msg.arbitration_id, reply_data, frame_bits(len(data)), arrival)

    def _reply(
        self, bus: can.BusABC, arbitration_id: int, data: bytes, request_bits: int, arrival: float
    ) -> None:
        fault = self._take_fault()
        frames: list[can.Message] = []
        if fault in ("checksum", "error_frame"):
            frames.append(can.Message(is_error_frame=True, is_extended_id=True))
        elif fault == "garble":  # CAN's own CRC rules out flipped bytes; what can go wrong is the length
            wrong_length = len(data) + 1 if len(data) < can_frames.MAX_DATA else 3
            frames.append(
                can.Message(
                    arbitration_id=arbitration_id, is_extended_id=True, data=self._noise(wrong_length, b"")
                )
            )
        elif fault == "partial":
            frames.append(
                can.Message(arbitration_id=arbitration_id, is_extended_id=True, data=data[: len(data) // 2])
            )
        elif fault != "drop":
            if fault == "noise":  # a frame for some other node first
                frames.append(
                    can.Message(arbitration_id=arbitration_id ^ 0x3FFF, is_extended_id=True, data=b"\x00")
                )
            frames.append(can.Message(arbitration_id=arbitration_id, is_extended_id=True, data=data))
        bits = request_bits + sum(
            ERROR_FRAME_BITS if m.is_error_frame else frame_bits(len(m.data)) for m in frames
        )
        self.wire_bits += bits
        self._wait_for_wire(arrival, bits / self.bitrate)
        for m in frames:
            try:
                bus.send(m)
            except can.CanOperationError:
                return
        self.replies_sent += 1 if frames else 0

"""Simulated hands on a pseudo-terminal: vendor `EB 90` frames, and Modbus RTU framed by pymodbus.

The Modbus device is a small RTU slave built from pymodbus' own RTU framer (CRC, frame sizing) and PDU
classes rather than pymodbus' async server: the simulator must corrupt, cut and delay individual replies at
byte level and pace them at the line rate, which the server does not expose.
"""

from __future__ import annotations

import time

from pymodbus.exceptions import ModbusException
from pymodbus.framer import FramerRTU
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
)

from deploy.hands import frames
from deploy.hands.frames import CMD_READ, CMD_WRITE, REQUEST_HEADER, FrameParser
from deploy.hands.sim_link import PtyLink
from deploy.hands.simulated import SimulatedHand

BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop
MODBUS_ILLEGAL_FUNCTION = 1
MODBUS_ILLEGAL_ADDRESS = 2
MODBUS_DEVICE_FAILURE = 4
MODBUS_MAX_READ = 125


class _PtyHand(SimulatedHand):
    def __init__(self, side: str, hand_id: int = 1, *, baudrate: int = 115200, echo: bool = False, **options):
        super().__init__(side, hand_id, **options)
        self.baudrate = int(baudrate)
        self.echo = echo  # behave like an RS485 adapter that hears its own transmission
        self.link = PtyLink(f"{self.transport}-{side}-{hand_id}")

    @property
    def port(self) -> str:
        """Stable path of the host end (a symlink to the current /dev/pts/N)."""
        return self.link.path

    def disconnect(self) -> None:
        self.link.unplug()

    def reconnect(self) -> None:
        self.link.plug()

    def _release(self) -> None:
        self.link.close()

    def bus_kwargs(self) -> dict:
        return {"port": self.port, "hand_id": self.hand_id, "baudrate": self.baudrate}

    @property
    def line_rate(self) -> float:
        return float(self.baudrate)

    def wire_seconds(self, nbytes: int) -> float:
        return nbytes * BITS_PER_BYTE / self.baudrate

    def _send(self, request: bytes, reply: bytes, arrival: float, avoid: bytes) -> None:
        out = self._apply_byte_fault(reply, self._take_fault(), avoid)
        self.wire_bits += (len(request) + len(out)) * BITS_PER_BYTE
        self._wait_for_wire(arrival, self.wire_seconds(len(request) + len(out)))
        if self.echo:
            out = request + out
        if out:
            self.link.write(out)
            self.replies_sent += 1


class SimulatedSerialHand(_PtyHand):
    transport = "serial"

    def __init__(self, side: str, hand_id: int = 1, **options):
        super().__init__(side, hand_id, **options)
        self._parser = FrameParser(REQUEST_HEADER)

    def _serve_once(self, timeout: float) -> None:
        data = self.link.read(timeout)
        if not data:
            return
        arrival = time.monotonic()
        for frame in self._parser.feed(data):
            self._handle(frame, arrival)

    def _handle(self, frame: frames.Frame, arrival: float) -> None:
        if frame.hand_id != self.hand_id:
            return  # another hand on the same RS485 bus
        group = self.registers.group_at(frame.address)
        name = group[1].name if group else f"@{frame.address}"
        if frame.cmd == CMD_READ and len(frame.payload) == 1 and frame.payload[0] > 0:
            self.requests[("read", name)] += 1
            data = self.registers.read(frame.address, frame.payload[0])
            reply = frames.encode_read_reply(frame.hand_id, frame.address, data)
        elif frame.cmd == CMD_WRITE:
            self.requests[("write", name)] += 1
            accepted = not self._take_refusal()
            if accepted:
                self.registers.write(frame.address, frame.payload)
            reply = frames.encode_write_ack(frame.hand_id, frame.address, ok=accepted)
        else:
            return
        self._send(frame.encode(), reply, arrival, avoid=frames.REPLY_HEADER[:1])


class SimulatedModbusHand(_PtyHand):
    transport = "modbus"

    def __init__(self, side: str, hand_id: int = 1, **options):
        super().__init__(side, hand_id, **options)
        self._framer = FramerRTU(DecodePDU(is_server=True))
        self._buf = b""
        self._last_rx = 0.0
        # RTU: 3.5 character times of silence end a frame (at least 1 ms: a pty gives no timing guarantees).
        self._t35 = max(3.5 * BITS_PER_BYTE / self.baudrate, 0.001)
        self._exception_faults = 0

    def exception_next(self, n: int = 1) -> None:
        """Answer the next n requests with Modbus exception 4 (slave device failure)."""
        self._exception_faults += int(n)

    def _serve_once(self, timeout: float) -> None:
        data = self.link.read(timeout)
        if not data:
            return
        arrival = time.monotonic()
        if self._buf and arrival - self._last_rx > self._t35:
            self._buf = b""  # silence ended the previous (incomplete) frame
        self._last_rx = arrival
        self._buf += data
        while self._buf:
            try:
                used, pdu = self._framer.handleFrame(self._buf, 0, 0)
            except ModbusException:
                self._buf = b""
                return
            self._buf = self._buf[used:]
            if pdu is None:
                return
            self._handle(pdu, arrival)

    def _handle(self, request: ModbusPDU, arrival: float) -> None:
        if request.dev_id not in (self.hand_id, 0):
            return  # another slave on the bus
        is_write = isinstance(request, WriteSingleRegisterRequest | WriteMultipleRegistersRequest)
        is_read = isinstance(request, ReadHoldingRegistersRequest)
        group = self.registers.group_at(request.address)
        name = group[1].name if group else f"@{request.address}"
        self.requests[("write" if is_write else "read" if is_read else "other", name)] += 1
        if self._exception_faults > 0 or (is_write and self._take_refusal()):
            self._exception_faults = max(0, self._exception_faults - 1)
            self.faults_applied["exception"] += 1
            response = ExceptionResponse(request.function_code, MODBUS_DEVICE_FAILURE)
        else:
            response = self._execute(request)
        if request.dev_id == 0:
            return  # broadcast: act, never answer
        response.dev_id = self.hand_id
        response.transaction_id = 0
        self._send(
            self._framer.buildFrame(request),
            self._framer.buildFrame(response),
            arrival,
            avoid=bytes([self.hand_id]),
        )

    def _execute(self, request: ModbusPDU) -> ModbusPDU:
        fc = request.function_code
        if isinstance(request, ReadHoldingRegistersRequest) and fc == 3:
            if not 1 <= request.count <= MODBUS_MAX_READ:
                return ExceptionResponse(fc, 3)
            words = self.registers.modbus_read(request.address, request.count)
            if words is None:
                return ExceptionResponse(fc, MODBUS_ILLEGAL_ADDRESS)
            return ReadHoldingRegistersResponse(registers=words)
        if isinstance(request, WriteSingleRegisterRequest):
            if not self.registers.modbus_write(request.address, [int(request.registers[0])]):
                return ExceptionResponse(fc, MODBUS_ILLEGAL_ADDRESS)
            return WriteSingleRegisterResponse(address=request.address, registers=list(request.registers))
        if isinstance(request, WriteMultipleRegistersRequest):
            words = [int(w) for w in request.registers]
            if len(words) != request.count or not self.registers.modbus_write(request.address, words):
                return ExceptionResponse(fc, MODBUS_ILLEGAL_ADDRESS)
            return WriteMultipleRegistersResponse(address=request.address, count=request.count)
        return ExceptionResponse(fc, MODBUS_ILLEGAL_FUNCTION)

"""Inspire hand over RS485 with Modbus RTU (pymodbus ModbusSerialClient; slave id = hand id).

Addressing follows the two working Modbus drivers (see tables.Register.modbus_layout): the start address is
the manual's byte address and each 16-bit element is one register (ANGLE_SET = 6 registers at 1486);
ERROR/STATUS/TEMP are 3 registers each with two u8 per register; single-byte system registers
(CLEAR_ERROR ...) are written as one whole register, as Unitree's SDK does. ERROR..TEMP is read as one
9-register request (1606..1623), the same byte-address reading that lets PyPI's driver read tip+nail tactile
blocks in one request.

pymodbus' sync serial client decides a reply is complete by polling the port every >= 1 ms until the byte
count stops growing, which adds 1-2 ms to every transaction (a third of the wire time at 115200 baud).
`_RtuClient` keeps the client and only replaces that wait: it returns as soon as pymodbus' own RTU framer
sees a complete frame, or after the standard 3.5-character silence.
"""

from __future__ import annotations

import select

import numpy as np
from pymodbus.client import ModbusSerialClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerRTU, FramerType
from pymodbus.pdu import DecodePDU, ModbusPDU
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersResponse,
    WriteMultipleRegistersResponse,
    WriteSingleRegisterResponse,
)

from deploy.hands import tables
from deploy.hands.register_bus import AttemptFailed, PortUnavailable, RegisterHandBus
from deploy.hands.tables import Register

DEFAULT_TIMEOUT_S = 0.03
FC_READ_HOLDING = 0x03
FC_WRITE_SINGLE = 0x06
FC_WRITE_MULTIPLE = 0x10
EXCEPTION_NAMES = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "slave device failure",
    6: "slave device busy",
}


class _RtuClient(ModbusSerialClient):
    """ModbusSerialClient whose receive returns at the end of the RTU frame instead of polling."""

    def recv(self, size: int | None) -> bytes:
        sock = self.socket
        if size is not None or sock is None or not hasattr(sock, "fileno"):
            return super().recv(size)
        t35 = max(3.5 * self._t0, 0.0005)
        try:
            buf = bytearray(sock.read(1))  # waits up to the client timeout for the first byte
            while buf:
                waiting = sock.in_waiting
                if waiting:
                    buf += sock.read(waiting)
                    continue
                if self.framer.decode(bytes(buf))[0]:
                    break  # a complete frame (good or bad CRC): pymodbus' framer takes it from here
                ready, _, _ = select.select([sock.fileno()], [], [], t35)
                if not ready:
                    break  # silence ends an RTU frame
            return bytes(buf)
        except (BlockingIOError, InterruptedError):
            raise
        except OSError:
            self.close()
            raise ConnectionException(str(self)) from None


def check_read_response(pdu: ModbusPDU | None, count: int) -> list[int] | None:
    """Register words of a good read-holding-registers response with exactly `count` registers."""
    if not isinstance(pdu, ReadHoldingRegistersResponse) or pdu.isError():
        return None
    words = list(pdu.registers)
    return words if len(words) == count else None


def parse_read_reply(raw: bytes, device_id: int, count: int) -> list[int] | None:
    """Decode a raw RTU reply exactly as the bus does (pymodbus' RTU framer + our checks); None if unusable."""
    framer = FramerRTU(DecodePDU(is_server=False))
    try:
        _, pdu = framer.handleFrame(raw, device_id, 0)
    except ModbusException:
        return None
    if pdu is None or pdu.dev_id != device_id:
        return None
    return check_read_response(pdu, count)


def diagnose_reply(raw: bytes, device_id: int, function_code: int) -> str:
    """Why `raw` (everything received during a failed try) was not a usable reply: an AttemptFailed kind."""
    if not raw:
        return "timeout"
    for i in range(len(raw) - 1):
        if raw[i] != device_id or raw[i + 1] not in (function_code, function_code | 0x80):
            continue
        if raw[i + 1] & 0x80:
            size = 5
        elif function_code == FC_READ_HOLDING:
            if i + 2 >= len(raw):
                return "partial"
            size = raw[i + 2] + 5
        else:
            size = 8
        if len(raw) - i < size:
            return "partial"
        frame = raw[i : i + size]
        if FramerRTU.compute_CRC(frame[:-2]) != int.from_bytes(frame[-2:], "big"):
            return "checksum"
        # A good frame after noise: pymodbus' framer drops the whole buffer when the noise looks like a frame.
        return "garbled" if i else "mismatch"
    return "garbled"


class ModbusHandBus(RegisterHandBus):
    """One hand on an RS485 port speaking Modbus RTU (8N1)."""

    transport = "modbus"

    def __init__(
        self,
        side: str,
        port: str,
        *,
        hand_id: int = 1,
        baudrate: int = 115200,
        timeout: float = DEFAULT_TIMEOUT_S,
        retries: int = 2,
        safe_pose="hold",
        handle_local_echo: bool = False,
    ):
        self.port = port
        self.baudrate = int(baudrate)
        self.handle_local_echo = bool(handle_local_echo)  # for RS485 adapters that echo what they send
        self._client: _RtuClient | None = None
        self._rx = b""
        super().__init__(
            side,
            hand_id=hand_id,
            timeout=timeout,
            retries=retries,
            safe_pose=safe_pose,
            hand_id_range=(1, 247),
        )

    def link_description(self) -> str:
        return f"Modbus RTU {self.port} @ {self.baudrate}"

    def _trace(self, sending: bool, data: bytes) -> bytes:
        self._rx = b"" if sending else data  # pymodbus hands us everything received so far for this request
        return data

    def _open(self) -> None:
        client = _RtuClient(
            self.port,
            framer=FramerType.RTU,
            baudrate=self.baudrate,
            bytesize=8,
            parity="N",
            stopbits=1,
            timeout=self.timeout,
            retries=0,  # retries are ours: logged, counted and classified
            handle_local_echo=self.handle_local_echo,
            trace_packet=self._trace,
        )
        if not client.connect():
            raise PortUnavailable(f"could not open serial port {self.port} (see the pymodbus log for why)")
        self._client = client

    def _close(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except OSError:
                pass
            self._client = None

    def _call(self, function_code: int, register: Register, request) -> ModbusPDU:
        client = self._client
        if client is None:
            raise AttemptFailed("disconnected", "port is closed")
        self._rx = b""
        try:
            response = request(client)
        except ConnectionException as exc:
            raise AttemptFailed("disconnected", str(exc)) from exc
        except ModbusIOException as exc:
            if not client.connected:
                raise AttemptFailed("disconnected", str(exc)) from exc
            kind = diagnose_reply(self._rx, self.hand_id, function_code)
            raise AttemptFailed(
                kind, f"{len(self._rx)} byte(s) received: {self._rx.hex(' ') or 'none'}"
            ) from exc
        except ModbusException as exc:
            raise AttemptFailed("garbled", str(exc)) from exc
        if response.isError():
            code = getattr(response, "exception_code", 0)
            raise self._fault(
                f"Modbus exception {code} ({EXCEPTION_NAMES.get(code, 'unknown')}) "
                f"for function 0x{function_code:02X} on {register.name}"
            )
        return response

    def _read_block(self, regs: tuple[Register, ...]) -> list[np.ndarray]:
        count = sum(r.modbus_count for r in regs)
        address = regs[0].address
        response = self._call(
            FC_READ_HOLDING,
            regs[0],
            lambda c: c.read_holding_registers(address, count=count, device_id=self.hand_id),
        )
        words = check_read_response(response, count)
        if words is None:
            raise AttemptFailed("mismatch", f"expected {count} registers, got {response}")
        out, offset = [], 0
        for reg in regs:
            out.append(tables.decode_modbus(reg, words[offset : offset + reg.modbus_count]))
            offset += reg.modbus_count
        return out

    def _write_register(self, reg: Register, values: np.ndarray) -> None:
        words = tables.encode_modbus(reg, values)
        if len(words) == 1:
            response = self._call(
                FC_WRITE_SINGLE,
                reg,
                lambda c: c.write_register(reg.address, words[0], device_id=self.hand_id),
            )
            ok = (
                isinstance(response, WriteSingleRegisterResponse)
                and response.address == reg.address
                and list(response.registers) == words
            )
        else:
            response = self._call(
                FC_WRITE_MULTIPLE,
                reg,
                lambda c: c.write_registers(reg.address, words, device_id=self.hand_id),
            )
            ok = (
                isinstance(response, WriteMultipleRegistersResponse)
                and response.address == reg.address
                and response.count == len(words)
            )
        if not ok:
            raise AttemptFailed("mismatch", f"write echo does not match {reg.name}: {response}")

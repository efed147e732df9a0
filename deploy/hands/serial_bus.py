"""Inspire hand over RS485 with the vendor's `EB 90` frames (pyserial; any pyserial port or URL)."""

from __future__ import annotations

import time

import numpy as np
import serial

from deploy.hands import frames, tables
from deploy.hands.frames import CMD_READ, CMD_WRITE, REPLY_HEADER, WRITE_ACK_OK, FrameParser
from deploy.hands.register_bus import AttemptFailed, PortUnavailable, RegisterHandBus
from deploy.hands.tables import Register

try:  # pyserial lets termios.error (not an OSError) escape from tcflush on a vanished tty
    from termios import error as _TermiosError
except ImportError:  # not POSIX
    _TermiosError = OSError

PORT_ERRORS = (serial.SerialException, OSError, _TermiosError)
DEFAULT_TIMEOUT_S = 0.03  # longest reply (26 B) takes 2.3 ms at 115200 baud; the hand adds a few ms


class SerialHandBus(RegisterHandBus):
    """One hand on an RS485 port (e.g. /dev/ttyUSB1), 8N1.

    Replies start with the reversed header `90 EB`, so an adapter that echoes our own `EB 90` request back is
    harmless: the reply parser skips it. Every request is answered by exactly one reply frame; a try fails when no reply with our hand id, command,
    address and length arrives within `timeout` (a try can last up to about 2x `timeout` when bytes keep
    trickling in), when the checksum is wrong, or when the port errors (then the next try reopens it).
    """

    transport = "serial"

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
    ):
        self.port = port
        self.baudrate = int(baudrate)
        self._serial: serial.SerialBase | None = None
        super().__init__(side, hand_id=hand_id, timeout=timeout, retries=retries, safe_pose=safe_pose)

    def link_description(self) -> str:
        return f"serial {self.port} @ {self.baudrate}"

    def _open(self) -> None:
        try:
            self._serial = serial.serial_for_url(
                self.port,
                baudrate=self.baudrate,
                bytesize=serial.EIGHTBITS,
                parity=serial.PARITY_NONE,
                stopbits=serial.STOPBITS_ONE,
                timeout=self.timeout,
                write_timeout=self.timeout,
                exclusive=True,
            )
        except (*PORT_ERRORS, ValueError) as exc:
            self._serial = None
            raise PortUnavailable(str(exc)) from exc

    def _close(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            except PORT_ERRORS:
                pass
            self._serial = None

    def _read_block(self, regs: tuple[Register, ...]) -> list[np.ndarray]:
        nbytes = sum(r.nbytes for r in regs)
        address = regs[0].address
        reply = self._exchange(frames.encode_read(self.hand_id, address, nbytes), CMD_READ, address, nbytes)
        out, offset = [], 0
        for reg in regs:
            out.append(tables.decode_values(reg, reply.payload[offset : offset + reg.nbytes]))
            offset += reg.nbytes
        return out

    def _write_register(self, reg: Register, values: np.ndarray) -> None:
        request = frames.encode_write(self.hand_id, reg.address, tables.encode_values(reg, values))
        ack = self._exchange(request, CMD_WRITE, reg.address, 1)
        if ack.payload[0] != WRITE_ACK_OK:
            raise self._fault(f"hand refused the write to {reg.name} (ack byte 0x{ack.payload[0]:02X})")

    def _exchange(self, request: bytes, cmd: int, address: int, payload_len: int) -> frames.Frame:
        port = self._serial
        if port is None:
            raise AttemptFailed("disconnected", "port is closed")
        try:
            port.reset_input_buffer()  # a late reply to an earlier try must not answer this one
            port.write(request)
        except PORT_ERRORS as exc:
            raise AttemptFailed("disconnected", f"write failed: {exc}") from exc
        parser = FrameParser(REPLY_HEADER)
        expected_size = payload_len + 3 + frames.OVERHEAD
        deadline = time.monotonic() + self.timeout
        mismatched = 0
        while True:
            try:
                chunk = port.read(max(1, expected_size - parser.pending))
            except PORT_ERRORS as exc:
                raise AttemptFailed("disconnected", f"read failed: {exc}") from exc
            for frame in parser.feed(chunk):
                if (
                    frame.hand_id == self.hand_id
                    and frame.cmd == cmd
                    and frame.address == address
                    and len(frame.payload) == payload_len
                ):
                    return frame
                mismatched += 1
            if time.monotonic() >= deadline:
                break
        raise _classify(parser, mismatched, self.timeout)


def _classify(parser: FrameParser, mismatched: int, timeout: float) -> AttemptFailed:
    counts = (
        f"{parser.bad_checksums} bad checksum(s), {parser.bad_lengths} bad length(s), "
        f"{parser.garbage_bytes} garbage byte(s), {parser.pending} byte(s) of an unfinished frame"
    )
    if parser.bad_checksums:
        return AttemptFailed("checksum", counts)
    if parser.pending and not parser.garbage_bytes:
        return AttemptFailed("partial", counts)
    if parser.garbage_bytes or parser.bad_lengths or parser.pending:
        return AttemptFailed("garbled", counts)
    if mismatched:
        return AttemptFailed("mismatch", f"{mismatched} reply frame(s) for another id, command or address")
    return AttemptFailed("timeout", f"no reply within {timeout * 1000:.0f} ms")

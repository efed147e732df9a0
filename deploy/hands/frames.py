"""Inspire private RS485 frames (`EB 90` requests, `90 EB` replies) and a streaming parser.

    EB 90 | ID | LEN | CMD | ADDR_L ADDR_H | payload ... | CHK

LEN counts CMD + address + payload (so a frame is LEN + 5 bytes). CHK is the low byte of the sum of every byte
from ID up to the byte before CHK. A read request's payload is one byte (how many bytes to read); its reply
carries those bytes. A write request carries the data; its ack carries one byte (0x01 = done).
"""

from __future__ import annotations

from dataclasses import dataclass

REQUEST_HEADER = b"\xeb\x90"
REPLY_HEADER = b"\x90\xeb"
CMD_READ = 0x11
CMD_WRITE = 0x12
WRITE_ACK_OK = 0x01
OVERHEAD = 5  # header (2) + ID + LEN + CHK; the rest of the frame is LEN bytes
MIN_LEN = 4  # CMD + 2 address bytes + at least one payload byte, true of every request and reply
MAX_LEN = 255  # LEN is one byte


def checksum(body: bytes) -> int:
    """Low byte of the sum of `body` (ID through the last payload byte)."""
    return sum(body) & 0xFF


@dataclass(frozen=True)
class Frame:
    header: bytes
    hand_id: int
    cmd: int
    address: int
    payload: bytes

    @property
    def is_reply(self) -> bool:
        return self.header == REPLY_HEADER

    def encode(self) -> bytes:
        if not 0 <= self.hand_id <= 0xFF:
            raise ValueError(f"hand id {self.hand_id} does not fit one byte")
        if not 0 <= self.address <= 0xFFFF:
            raise ValueError(f"address {self.address} does not fit two bytes")
        length = 3 + len(self.payload)
        if not MIN_LEN <= length <= MAX_LEN:
            raise ValueError(
                f"payload of {len(self.payload)} bytes gives LEN {length}, outside {MIN_LEN}..{MAX_LEN}"
            )
        body = bytes([self.hand_id, length, self.cmd]) + self.address.to_bytes(2, "little") + self.payload
        return self.header + body + bytes([checksum(body)])


def encode_read(hand_id: int, address: int, nbytes: int) -> bytes:
    if not 1 <= nbytes <= MAX_LEN - 3:
        raise ValueError(f"cannot read {nbytes} bytes in one frame")
    return Frame(REQUEST_HEADER, hand_id, CMD_READ, address, bytes([nbytes])).encode()


def encode_write(hand_id: int, address: int, data: bytes) -> bytes:
    return Frame(REQUEST_HEADER, hand_id, CMD_WRITE, address, bytes(data)).encode()


def encode_read_reply(hand_id: int, address: int, data: bytes) -> bytes:
    return Frame(REPLY_HEADER, hand_id, CMD_READ, address, bytes(data)).encode()


def encode_write_ack(hand_id: int, address: int, ok: bool = True) -> bytes:
    return Frame(REPLY_HEADER, hand_id, CMD_WRITE, address, bytes([WRITE_ACK_OK if ok else 0x00])).encode()


def read_reply_size(nbytes: int) -> int:
    """Bytes on the wire for the reply to a read of `nbytes`."""
    return nbytes + 3 + OVERHEAD


def write_request_size(nbytes: int) -> int:
    return nbytes + 3 + OVERHEAD


READ_REQUEST_SIZE = 1 + 3 + OVERHEAD  # 9
WRITE_ACK_SIZE = 1 + 3 + OVERHEAD  # 9


class FrameParser:
    """Finds frames with one header in a byte stream fed in arbitrary chunks.

    Resynchronises on garbage: a candidate header whose checksum fails is dropped one byte at a time, so a
    real frame that starts inside a bad one is still found. A candidate that is still incomplete does not block
    a complete, valid frame that starts after it (a stray `90 EB` in noise must not swallow the real reply).
    Counters say what was thrown away, so a caller can tell "no reply" from "bad checksum" or "partial frame".
    """

    def __init__(self, header: bytes = REPLY_HEADER, max_len: int = MAX_LEN):
        if len(header) != 2:
            raise ValueError("header must be 2 bytes")
        self.header = header
        self.max_len = max(MIN_LEN, min(MAX_LEN, max_len))
        self._buf = bytearray()
        self.frames = 0
        self.bad_checksums = 0
        self.bad_lengths = 0
        self.garbage_bytes = 0

    @property
    def pending(self) -> int:
        """Bytes held back as the start of a frame not yet complete."""
        return len(self._buf)

    def reset(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        frames: list[Frame] = []
        while True:
            found = self._next_frame()
            if found is None:
                return frames
            frames.append(found)

    def _candidate(self, start: int) -> tuple[str, int]:
        """(verdict, frame size) for a header at `start`: ok, short (wait for more), bad_length, bad_checksum."""
        buf = self._buf
        if start + 4 > len(buf):
            return "short", 0
        length = buf[start + 3]
        if not MIN_LEN <= length <= self.max_len:
            return "bad_length", 0
        size = length + OVERHEAD
        if start + size > len(buf):
            return "short", size
        if checksum(buf[start + 2 : start + size - 1]) != buf[start + size - 1]:
            return "bad_checksum", size
        return "ok", size

    def _next_frame(self) -> Frame | None:
        buf = self._buf
        rejected: list[tuple[int, str]] = []  # counted only once their bytes are dropped
        pending_start = -1
        frame_start = size = -1
        pos = buf.find(self.header)
        while pos != -1:
            verdict, size = self._candidate(pos)
            if verdict == "ok":
                frame_start = pos
                break
            if verdict == "short":
                if pending_start < 0:
                    pending_start = pos
            else:
                rejected.append((pos, verdict))
            pos = buf.find(self.header, pos + 1)
        if frame_start < 0:
            # No complete valid frame: keep the earliest incomplete candidate (or a trailing header byte).
            keep_from = pending_start if pending_start >= 0 else self._trailing_header_start()
            self._drop(keep_from, rejected)
            return None
        self._drop(frame_start, rejected)
        frame_bytes = bytes(buf[:size])
        del buf[:size]
        self.frames += 1
        payload_len = frame_bytes[3] - 3
        return Frame(
            header=self.header,
            hand_id=frame_bytes[2],
            cmd=frame_bytes[4],
            address=frame_bytes[5] | (frame_bytes[6] << 8),
            payload=frame_bytes[7 : 7 + payload_len],
        )

    def _trailing_header_start(self) -> int:
        if self._buf and self._buf[-1] == self.header[0]:
            return len(self._buf) - 1
        return len(self._buf)

    def _drop(self, n: int, rejected: list[tuple[int, str]]) -> None:
        for pos, verdict in rejected:
            if pos < n:
                if verdict == "bad_length":
                    self.bad_lengths += 1
                else:
                    self.bad_checksums += 1
        if n > 0:
            self.garbage_bytes += n
            del self._buf[:n]

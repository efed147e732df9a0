"""Inspire CAN 2.0B frames: 29-bit identifiers, request/reply matching and classic-CAN chunking.

    id = (rw << 26) | (address << 14) | hand_id      rw: 0 read, 1 write (4/5: wrist registers, unused here)

A read request carries one byte, the number of bytes wanted; the reply has the same id and those bytes
(little-endian elements). A write carries the data; the ack has the same id and 0 or 1 data bytes (the manual
says DLC 1, a hardware capture shows no data; both are accepted).

Classic CAN carries 8 data bytes, so a 6-DoF group (12 bytes) never fits one frame, and how the hand answers a
read of more than 8 bytes is undocumented. Our choice: split every register group on its own, into element-
aligned chunks of at most 8 bytes (12 -> 8 + 4; a 6-byte u8 group -> 6), and never let a chunk straddle two
groups. `chunk_bytes=2` gives the per-register reads/writes the CAN analysis' driver uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import can

from deploy.hands.tables import Register

RW_READ = 0
RW_WRITE = 1
VALID_RW = (0, 1, 4, 5)
MAX_ADDRESS = (1 << 12) - 1
MAX_HAND_ID = (1 << 14) - 1
MAX_DATA = 8


def make_id(rw: int, address: int, hand_id: int) -> int:
    if rw not in VALID_RW:
        raise ValueError(f"CAN rw flag must be one of {VALID_RW}, got {rw}")
    if not 0 <= address <= MAX_ADDRESS:
        raise ValueError(f"CAN register address {address} does not fit 12 bits")
    if not 0 <= hand_id <= MAX_HAND_ID:
        raise ValueError(f"CAN hand id {hand_id} does not fit 14 bits")
    return (rw << 26) | (address << 14) | hand_id


@dataclass(frozen=True)
class CanId:
    rw: int
    address: int
    hand_id: int


def parse_id(arbitration_id: int) -> CanId | None:
    """Split a 29-bit id; None when it cannot be an Inspire id (bits 29-31 set, unknown rw flag)."""
    if not 0 <= arbitration_id < (1 << 29):
        return None
    rw = arbitration_id >> 26
    if rw not in VALID_RW:
        return None
    return CanId(rw, (arbitration_id >> 14) & MAX_ADDRESS, arbitration_id & MAX_HAND_ID)


def frame_bits(nbytes: int) -> int:
    """Bits of an extended data frame with `nbytes` of data, without stuffing bits (so a lower bound):
    SOF 1, id 11+18, SRR, IDE, RTR, r1, r0, DLC 4, data, CRC 15 + delimiter, ACK 2, EOF 7, interframe 3."""
    return 67 + 8 * nbytes


ERROR_FRAME_BITS = 20  # 6-12 bit error flag + 8 bit delimiter + 3 bit interframe space


def chunks(reg: Register, address: int, chunk_bytes: int = MAX_DATA) -> list[tuple[int, int]]:
    """(address, nbytes) pieces of one register group, element-aligned, at most chunk_bytes each."""
    per = max(reg.size, (min(chunk_bytes, MAX_DATA) // reg.size) * reg.size)
    return [(address + off, min(per, reg.nbytes - off)) for off in range(0, reg.nbytes, per)]


@dataclass(frozen=True)
class Pending:
    """A request on the wire and what its reply must look like."""

    rw: int
    address: int
    hand_id: int
    data: bytes  # request payload (read: one byte = length wanted)
    register: str = ""  # register group name, for messages

    @cached_property
    def arbitration_id(self) -> int:
        return make_id(self.rw, self.address, self.hand_id)

    @property
    def reply_length(self) -> int | None:
        """Exact data length of a good reply (None for a write ack: 0 or 1 byte)."""
        return self.data[0] if self.rw == RW_READ else None

    @cached_property
    def message(self) -> can.Message:
        """The request frame (built once; python-can interfaces do not modify what they send)."""
        return can.Message(arbitration_id=self.arbitration_id, is_extended_id=True, data=self.data)


def classify_reply(msg: can.Message, pending: Pending) -> str:
    """'ok' | 'error_frame' | 'partial' (too short) | 'garbled' (too long) | 'unrelated' for a received frame."""
    if msg.is_error_frame:
        return "error_frame"
    if msg.is_remote_frame or not msg.is_extended_id or msg.arbitration_id != pending.arbitration_id:
        return "unrelated"
    n = len(msg.data)
    if n != msg.dlc:
        return "garbled"
    want = pending.reply_length
    if want is None:
        return "ok" if n <= 1 else "garbled"
    if n == want:
        return "ok"
    return "partial" if n < want else "garbled"


def parse_request(msg: can.Message, hand_id: int) -> tuple[int, int, bytes] | None:
    """Device side: (rw, address, data) of a well-formed read/write request to `hand_id`, else None."""
    if msg.is_error_frame or msg.is_remote_frame or not msg.is_extended_id:
        return None
    cid = parse_id(msg.arbitration_id)
    if cid is None or cid.hand_id != hand_id or cid.rw not in (RW_READ, RW_WRITE):
        return None
    data = bytes(msg.data)
    if len(data) != msg.dlc or not 1 <= len(data) <= MAX_DATA:
        return None
    if cid.rw == RW_READ and (len(data) != 1 or not 1 <= data[0] <= MAX_DATA):
        return None
    return cid.rw, cid.address, data

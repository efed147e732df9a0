"""Inspire RH56 register map as data, plus the value codecs each transport needs.

Addresses are the manual's byte addresses (RS485 vendor frames, Modbus start addresses and, with the few
exceptions in CAN_ADDRESSES, the 12-bit CAN address field). 16-bit elements are little-endian in the vendor
and CAN frames; Modbus carries each 16-bit element as one big-endian register.

DoF order in every 6-element group: pinky, ring, middle, index, thumb bend, thumb rotation.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from deploy.hand_units import INSPIRE_CHANNELS

NUM_DOF = len(INSPIRE_CHANNELS)

# name: (byte address, element count, element size in bytes, signed, access, min, max)
REGISTER_TABLE: dict[str, tuple[int, int, int, bool, str, int, int]] = {
    "HAND_ID": (1000, 1, 1, False, "RW", 1, 254),
    "REDU_RATIO": (1002, 1, 1, False, "RW", 0, 3),
    "CLEAR_ERROR": (1004, 1, 1, False, "RW", 0, 1),
    "SAVE": (1005, 1, 1, False, "RW", 0, 1),
    "RESET_PARA": (1006, 1, 1, False, "RW", 0, 1),
    "GESTURE_FORCE_CLB": (1009, 1, 1, False, "RW", 0, 1),
    "DEFAULT_SPEED_SET": (1032, 6, 2, True, "RW", 0, 1000),
    "DEFAULT_FORCE_SET": (1044, 6, 2, True, "RW", 0, 3000),
    "POS_SET": (1474, 6, 2, True, "RW", -1, 2000),
    "ANGLE_SET": (
        1486,
        6,
        2,
        True,
        "RW",
        0,
        1000,
    ),  # the device also takes -1 = leave alone; we never send it
    "FORCE_SET": (1498, 6, 2, True, "RW", 0, 3000),  # grams at the fingertip
    "SPEED_SET": (1522, 6, 2, True, "RW", 0, 1000),  # 1000 ~ 0.6 s for a no-load full stroke
    "POS_ACT": (1534, 6, 2, True, "R", 0, 2000),
    "ANGLE_ACT": (1546, 6, 2, True, "R", 0, 1000),
    "FORCE_ACT": (1582, 6, 2, True, "R", -4000, 4000),
    "CURRENT": (1594, 6, 2, True, "R", 0, 2000),
    "ERROR": (1606, 6, 1, False, "R", 0, 255),
    "STATUS": (1612, 6, 1, False, "R", 0, 255),
    "TEMP": (1618, 6, 1, False, "R", 0, 100),
}

# The CAN firmware moves these system registers (CAN supplement protocol V0.0.2 as analysed in the notes).
# Whether RESET_PARA and GESTURE_FORCE_CLB move too is undocumented: we assume they do not (unverified).
CAN_ADDRESSES: dict[str, int] = {"HAND_ID": 250, "REDU_RATIO": 4008, "CLEAR_ERROR": 4016, "SAVE": 4020}

# ERROR register bits (per finger).
ERROR_BITS: dict[int, str] = {
    0: "locked rotor",
    1: "over-temperature",
    2: "over-current",
    3: "motor abnormal",
    4: "communication",
}
ERROR_LOCKED_ROTOR, ERROR_OVER_TEMPERATURE, ERROR_OVER_CURRENT, ERROR_MOTOR, ERROR_COMMUNICATION = (
    1 << bit for bit in range(5)
)

# STATUS codes (from Unitree's inspire_hand_sdk defaults; the manual extract has no table).
STATUS_RELEASING, STATUS_GRASPING, STATUS_AT_TARGET, STATUS_AT_FORCE_LIMIT = 0, 1, 2, 3
STATUS_CODES: dict[int, str] = {
    STATUS_RELEASING: "releasing",
    STATUS_GRASPING: "grasping",
    STATUS_AT_TARGET: "stopped at target",
    STATUS_AT_FORCE_LIMIT: "stopped at force limit",
    5: "stopped by current protection",
    6: "stalled",
    7: "actuator fault",
    255: "error",
}

# Blocks read every state cycle, each one request. ERROR..TEMP is one 18-byte span, as in the manual's example.
STATE_BLOCKS: tuple[tuple[str, ...], ...] = (("ANGLE_ACT",), ("FORCE_ACT",), ("ERROR", "STATUS", "TEMP"))


@dataclass(frozen=True)
class Register:
    name: str
    address: int
    count: int
    size: int
    signed: bool
    access: str
    low: int
    high: int

    @property
    def nbytes(self) -> int:
        return self.count * self.size

    @property
    def writable(self) -> bool:
        return "W" in self.access

    @property
    def can_address(self) -> int:
        return CAN_ADDRESSES.get(self.name, self.address)

    @property
    def modbus_layout(self) -> str:
        """How Modbus carries this group (both working Modbus drivers address registers by byte address).

        "i16": one register per 16-bit element. "u8": a single-byte system register written/read as one whole
        register (Unitree's SDK writes 1 to register 1004 to clear errors). "u8_pairs": a 6-byte group read as
        3 registers holding two elements each, high byte first as Unitree's SDK decodes them (unverified).
        """
        if self.size == 2:
            return "i16"
        return "u8" if self.count == 1 else "u8_pairs"

    @property
    def modbus_count(self) -> int:
        return self.count if self.modbus_layout in ("i16", "u8") else (self.count + 1) // 2

    def element_address(self, i: int) -> int:
        """Byte address of element i (e.g. ANGLE_SET[3] = 1492, ERROR[3] = 1609)."""
        if not 0 <= i < self.count:
            raise IndexError(f"{self.name} has {self.count} elements, not index {i}")
        return self.address + i * self.size


REGISTERS: dict[str, Register] = {name: Register(name, *row) for name, row in REGISTER_TABLE.items()}


def register_at(address: int) -> Register | None:
    """The register group whose bytes cover `address` (RS485 byte addressing), or None."""
    for reg in REGISTERS.values():
        if reg.address <= address < reg.address + reg.nbytes:
            return reg
    return None


def contiguous(names: Sequence[str]) -> tuple[Register, ...]:
    """Registers for `names`, checked to form one gap-free byte span in the given order."""
    regs = tuple(REGISTERS[n] for n in names)
    for a, b in zip(regs, regs[1:], strict=False):
        if a.address + a.nbytes != b.address:
            raise ValueError(
                f"{a.name} and {b.name} are not adjacent ({a.address}+{a.nbytes} != {b.address})"
            )
    return regs


_STRUCT_CODES = {(2, True): "h", (2, False): "H", (1, True): "b", (1, False): "B"}


def _format(reg: Register) -> str:
    return "<" + _STRUCT_CODES[(reg.size, reg.signed)] * reg.count


def encode_values(reg: Register, values: Sequence[int]) -> bytes:
    """Element values -> little-endian bytes as they travel in vendor and CAN frames."""
    if len(values) != reg.count:
        raise ValueError(f"{reg.name} takes {reg.count} values, got {len(values)}")
    try:
        return struct.pack(_format(reg), *(int(v) for v in values))
    except struct.error as exc:
        raise ValueError(f"{reg.name}: a value does not fit the register: {list(values)}") from exc


def decode_values(reg: Register, data: bytes) -> np.ndarray:
    """Little-endian bytes -> (count,) int64 values."""
    if len(data) != reg.nbytes:
        raise ValueError(f"{reg.name} is {reg.nbytes} bytes, got {len(data)}")
    return np.array(struct.unpack(_format(reg), data), dtype=np.int64)


def encode_modbus(reg: Register, values: Sequence[int]) -> list[int]:
    """Element values -> Modbus register words (0..65535) following `reg.modbus_layout`."""
    raw = encode_values(reg, values)  # validates count and range
    if reg.modbus_layout == "i16":
        return [raw[i] | (raw[i + 1] << 8) for i in range(0, len(raw), 2)]
    if reg.modbus_layout == "u8":
        return [raw[0]]
    padded = raw + b"\x00" * (len(raw) % 2)
    return [(padded[i] << 8) | padded[i + 1] for i in range(0, len(padded), 2)]


def decode_modbus(reg: Register, words: Sequence[int]) -> np.ndarray:
    """Modbus register words -> (count,) int64 element values following `reg.modbus_layout`."""
    if len(words) != reg.modbus_count:
        raise ValueError(f"{reg.name} is {reg.modbus_count} Modbus registers, got {len(words)}")
    if any(not 0 <= int(w) <= 0xFFFF for w in words):
        raise ValueError(f"{reg.name}: Modbus register word out of 0..65535: {list(words)}")
    if reg.modbus_layout == "i16":
        raw = b"".join(int(w).to_bytes(2, "little") for w in words)
    elif reg.modbus_layout == "u8":
        if int(words[0]) > 0xFF:
            raise ValueError(f"{reg.name}: single-byte register holds {int(words[0])}")
        raw = bytes([int(words[0])])
    else:
        raw = b"".join(int(w).to_bytes(2, "big") for w in words)[: reg.nbytes]
    return decode_values(reg, raw)


def describe_errors(errors: Sequence[int]) -> str:
    """'index: locked rotor; thumb_bend: over-temperature+over-current' for the non-zero ERROR bytes."""
    parts = []
    for dof, bits in zip(INSPIRE_CHANNELS, errors, strict=True):
        bits = int(bits)
        if bits:
            names = [name for bit, name in ERROR_BITS.items() if bits & (1 << bit)]
            unknown = bits & ~sum(1 << b for b in ERROR_BITS)
            if unknown:
                names.append(f"unknown bits 0x{unknown:02X}")
            parts.append(f"{dof}: {'+'.join(names)}")
    return "; ".join(parts)

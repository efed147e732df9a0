"""Register file of a simulated hand: byte-addressed memory tied to a FingerModel.

Reads of live registers (ANGLE_ACT, FORCE_ACT, ERROR, ...) are refreshed from the model first; writes to
ANGLE_SET / FORCE_SET / SPEED_SET / CLEAR_ERROR / HAND_ID reach the model (or the device id). Every write is
logged as the element values that arrived, so tests can spy on exactly what went over the wire.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from deploy.hands import tables
from deploy.hands.finger_model import FingerModel
from deploy.hands.tables import REGISTERS, Register

LIVE = ("ANGLE_ACT", "FORCE_ACT", "POS_ACT", "CURRENT", "ERROR", "STATUS", "TEMP")


@dataclass(frozen=True)
class WriteRecord:
    register: str
    first: int  # index of the first element written
    values: tuple[int, ...]


class DeviceRegisters:
    """`can=True` uses the CAN firmware's addresses for the moved system registers."""

    def __init__(self, model: FingerModel, hand_id: int, can: bool = False):
        self.model = model
        self._address = {name: (reg.can_address if can else reg.address) for name, reg in REGISTERS.items()}
        self._by_address = sorted((addr, REGISTERS[name]) for name, addr in self._address.items())
        self.mem = bytearray(1 << 16)
        self.writes: list[WriteRecord] = []
        self.overrides: dict[tuple[str, int], int] = {}  # (register, element) -> value read instead of the model's
        self._lock = threading.Lock()
        self._put("HAND_ID", [hand_id])
        self._put("ANGLE_SET", model.angle_set)
        self._put("SPEED_SET", model.speed_set)
        self._put("FORCE_SET", model.force_set)
        self._put("DEFAULT_SPEED_SET", model.speed_set)
        self._put("DEFAULT_FORCE_SET", model.force_set)

    @property
    def hand_id(self) -> int:
        return self.mem[self._address["HAND_ID"]]

    def group_at(self, address: int) -> tuple[int, Register] | None:
        """(start address, register) of the group covering `address` in this device's address map."""
        for start, reg in self._by_address:
            if start <= address < start + reg.nbytes:
                return start, reg
        return None

    # ----------------------------------------------------------------- byte access (vendor frames, CAN)
    def read(self, address: int, nbytes: int) -> bytes:
        with self._lock:
            self._refresh(address, nbytes)
            return bytes(self.mem[address : address + nbytes])

    def write(self, address: int, data: bytes) -> None:
        with self._lock:
            self.mem[address : address + len(data)] = data
            self._log_and_apply(address, len(data))

    # ----------------------------------------------------------------- Modbus access
    def modbus_read(self, address: int, count: int) -> list[int] | None:
        """Register words for a read of `count` registers at `address`; None = illegal data address."""
        with self._lock:
            spans = self._modbus_spans(address, count)
            if spans is None:
                return None
            self._refresh(address, spans[-1][0] + spans[-1][1] - address)
            return [self._word(a, n, reg) for a, n, reg in spans]

    def modbus_write(self, address: int, words: list[int]) -> bool:
        with self._lock:
            spans = self._modbus_spans(address, len(words))
            if spans is None:
                return False
            for (a, n, reg), word in zip(spans, words, strict=True):
                if n == 1:
                    self.mem[a] = word & 0xFF
                elif reg.modbus_layout == "u8_pairs":
                    self.mem[a : a + 2] = word.to_bytes(2, "big")
                else:
                    self.mem[a : a + 2] = word.to_bytes(2, "little")
            end = spans[-1][0] + spans[-1][1]
            self._log_and_apply(address, end - address)
            return True

    def _modbus_spans(self, address: int, count: int) -> list[tuple[int, int, Register]] | None:
        """Byte spans (address, size, register) of `count` Modbus registers from `address`."""
        spans, a = [], address
        for _ in range(count):
            found = self.group_at(a)
            if found is None:
                return None
            start, reg = found
            size = 1 if reg.modbus_layout == "u8" else 2
            if (a - start) % size:
                return None
            spans.append((a, size, reg))
            a += size
        return spans

    def _word(self, a: int, size: int, reg: Register) -> int:
        if size == 1:
            return self.mem[a]
        if reg.modbus_layout == "u8_pairs":
            return int.from_bytes(self.mem[a : a + 2], "big")
        return int.from_bytes(self.mem[a : a + 2], "little")

    # ----------------------------------------------------------------- model coupling
    def _groups_in(self, address: int, nbytes: int) -> list[tuple[int, Register]]:
        return [(s, r) for s, r in self._by_address if s < address + nbytes and address < s + r.nbytes]

    def _put(self, name: str, values) -> None:
        start = self._address[name]
        reg = REGISTERS[name]
        self.mem[start : start + reg.nbytes] = tables.encode_values(reg, [int(v) for v in values])

    def _get(self, name: str) -> np.ndarray:
        start = self._address[name]
        reg = REGISTERS[name]
        return tables.decode_values(reg, bytes(self.mem[start : start + reg.nbytes]))

    def _refresh(self, address: int, nbytes: int) -> None:
        groups = [r.name for _, r in self._groups_in(address, nbytes)]
        if any(name in LIVE for name in groups):
            measured = self.model.measure()
            for name in groups:
                if name in LIVE:
                    values = list(measured[name])
                    for (register, i), value in self.overrides.items():
                        values[i] = value if register == name else values[i]
                    self._put(name, values)

    def _log_and_apply(self, address: int, nbytes: int) -> None:
        for start, reg in self._groups_in(address, nbytes):
            lo = max(address, start)
            hi = min(address + nbytes, start + reg.nbytes)
            first = (lo - start) // reg.size
            last = (hi - start + reg.size - 1) // reg.size
            values = self._get(reg.name)
            self.writes.append(WriteRecord(reg.name, first, tuple(int(v) for v in values[first:last])))
            if reg.name == "ANGLE_SET":
                self.model.command(angle_set=values)
            elif reg.name == "SPEED_SET":
                self.model.command(speed_set=values)
            elif reg.name == "FORCE_SET":
                self.model.command(force_set=values)
            elif reg.name == "CLEAR_ERROR" and values[0] == 1:
                self.model.clear_errors()
                self._put("CLEAR_ERROR", [0])

"""Unitree G1 ("hg" family) LowCmd / LowState byte layout and CRC, in pure Python (no DDS needed).

The robot drops a LowCmd whose `crc` field is wrong. The CRC is computed over the message laid out as the C
struct (little-endian, natural alignment):

    LowCmd   '<2B2x' + 'B3x5fI' * 35 + '5I'                       1004 bytes
             mode_pr, mode_machine | 35 x (mode, q, dq, tau, kp, kd, reserve) | reserve[4], crc
    LowState '<2I2B2xI' + '13fh2x' + 'B3x4f2hf7I' * 35 + '40B5I'  2092 bytes
             version[2], mode_pr, mode_machine, tick | imu (quat wxyz, gyro, acc, rpy, temp) |
             35 x (mode, q, dq, ddq, tau_est, temperature[2], vol, sensor[2], motorstate, reserve[4]) |
             wireless_remote[40], reserve[4], crc

CRC: the buffer read as little-endian uint32 words without the last (crc) word, CRC-32 polynomial 0x04C11DB7,
initial value 0xFFFFFFFF, no reflection, no final xor, each word fed most significant bit first (the STM32
hardware CRC). That equals CRC-32/MPEG-2 over the words written big-endian, which we compute with zlib's
reflected CRC-32 on bit-reversed bytes (C speed; the bitwise definition is in the tests as the reference).
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass, field

import numpy as np

NUM_MOTOR_SLOTS = 35
LOWCMD_STRUCT = struct.Struct("<2B2x" + "B3x5fI" * NUM_MOTOR_SLOTS + "5I")
LOWSTATE_STRUCT = struct.Struct("<2I2B2xI" + "13fh2x" + "B3x4f2hf7I" * NUM_MOTOR_SLOTS + "40B5I")
MOTOR_MODE_ENABLE = 1

_BIT_REVERSED = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def unitree_crc32(buffer: bytes) -> int:
    """CRC of a packed message: every little-endian uint32 word except the last one (the crc field)."""
    if len(buffer) % 4:
        raise ValueError(f"message length {len(buffer)} is not a multiple of 4")
    words_msb_first = np.frombuffer(buffer[:-4], dtype="<u4").astype(">u4").tobytes()
    register = binascii.crc32(words_msb_first.translate(_BIT_REVERSED)) ^ 0xFFFFFFFF
    return int(f"{register:032b}"[::-1], 2)


def _slots(values, dtype) -> np.ndarray:
    return np.zeros(NUM_MOTOR_SLOTS, dtype=dtype) if values is None else np.asarray(values, dtype=dtype)


@dataclass
class LowCmdFrame:
    mode_pr: int = 0
    mode_machine: int = 0
    motor_mode: np.ndarray = field(default_factory=lambda: _slots(None, np.uint8))
    q: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    dq: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    tau: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    kp: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    kd: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    motor_reserve: np.ndarray = field(default_factory=lambda: _slots(None, np.uint32))
    reserve: np.ndarray = field(default_factory=lambda: np.zeros(4, dtype=np.uint32))
    crc: int = 0

    def pack(self) -> bytes:
        values: list = [int(self.mode_pr), int(self.mode_machine)]
        for i in range(NUM_MOTOR_SLOTS):
            values += [int(self.motor_mode[i]), float(self.q[i]), float(self.dq[i]), float(self.tau[i]),
                       float(self.kp[i]), float(self.kd[i]), int(self.motor_reserve[i])]
        values += [int(v) for v in self.reserve] + [int(self.crc)]
        return LOWCMD_STRUCT.pack(*values)

    def with_crc(self) -> LowCmdFrame:
        self.crc = unitree_crc32(self.pack())
        return self

    def crc_ok(self) -> bool:
        """True when the crc field matches the content (what the robot checks before acting)."""
        return unitree_crc32(self.pack()) == self.crc

    @classmethod
    def unpack(cls, buffer: bytes) -> LowCmdFrame:
        v = LOWCMD_STRUCT.unpack(buffer)
        motors = np.array(v[2 : 2 + 7 * NUM_MOTOR_SLOTS], dtype=np.float64).reshape(NUM_MOTOR_SLOTS, 7)
        return cls(
            mode_pr=v[0],
            mode_machine=v[1],
            motor_mode=motors[:, 0].astype(np.uint8),
            q=motors[:, 1].astype(np.float32),
            dq=motors[:, 2].astype(np.float32),
            tau=motors[:, 3].astype(np.float32),
            kp=motors[:, 4].astype(np.float32),
            kd=motors[:, 5].astype(np.float32),
            motor_reserve=motors[:, 6].astype(np.uint32),
            reserve=np.array(v[-5:-1], dtype=np.uint32),
            crc=v[-1],
        )


def make_lowcmd(
    q: np.ndarray,
    dq: np.ndarray,
    kp: np.ndarray,
    kd: np.ndarray,
    tau: np.ndarray,
    mode_machine: int,
    mode_pr: int = 0,
) -> LowCmdFrame:
    """A LowCmd for the first len(q) motors (enabled) with the CRC filled in; the other slots stay zero."""
    frame = LowCmdFrame(mode_pr=mode_pr, mode_machine=mode_machine)
    n = len(q)
    frame.motor_mode[:n] = MOTOR_MODE_ENABLE
    frame.q[:n], frame.dq[:n], frame.kp[:n], frame.kd[:n], frame.tau[:n] = q, dq, kp, kd, tau
    return frame.with_crc()


@dataclass
class LowStateFrame:
    version: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=np.uint32))
    mode_pr: int = 0
    mode_machine: int = 0
    tick: int = 0
    imu_quat_wxyz: np.ndarray = field(default_factory=lambda: np.array([1, 0, 0, 0], dtype=np.float32))
    imu_gyro: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.float32))
    imu_acc: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.float32))
    imu_rpy: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.float32))
    imu_temperature: int = 0
    motor_mode: np.ndarray = field(default_factory=lambda: _slots(None, np.uint8))
    q: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    dq: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    ddq: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    tau_est: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    temperature: np.ndarray = field(default_factory=lambda: np.zeros((NUM_MOTOR_SLOTS, 2), dtype=np.int16))
    vol: np.ndarray = field(default_factory=lambda: _slots(None, np.float32))
    sensor: np.ndarray = field(default_factory=lambda: np.zeros((NUM_MOTOR_SLOTS, 2), dtype=np.uint32))
    motorstate: np.ndarray = field(default_factory=lambda: _slots(None, np.uint32))
    motor_reserve: np.ndarray = field(default_factory=lambda: np.zeros((NUM_MOTOR_SLOTS, 4), dtype=np.uint32))
    wireless_remote: np.ndarray = field(default_factory=lambda: np.zeros(40, dtype=np.uint8))
    reserve: np.ndarray = field(default_factory=lambda: np.zeros(4, dtype=np.uint32))
    crc: int = 0

    def pack(self) -> bytes:
        values: list = [int(v) for v in self.version] + [int(self.mode_pr), int(self.mode_machine), int(self.tick)]
        values += [float(v) for v in (*self.imu_quat_wxyz, *self.imu_gyro, *self.imu_acc, *self.imu_rpy)]
        values.append(int(self.imu_temperature))
        for i in range(NUM_MOTOR_SLOTS):
            values += [int(self.motor_mode[i]), float(self.q[i]), float(self.dq[i]), float(self.ddq[i]),
                       float(self.tau_est[i]), int(self.temperature[i, 0]), int(self.temperature[i, 1]),
                       float(self.vol[i]), int(self.sensor[i, 0]), int(self.sensor[i, 1]),
                       int(self.motorstate[i]), *(int(r) for r in self.motor_reserve[i])]
        values += [int(v) for v in self.wireless_remote] + [int(v) for v in self.reserve] + [int(self.crc)]
        return LOWSTATE_STRUCT.pack(*values)

    def with_crc(self) -> LowStateFrame:
        self.crc = unitree_crc32(self.pack())
        return self

    def crc_ok(self) -> bool:
        return unitree_crc32(self.pack()) == self.crc

"""LowCmd / LowState packing and the CRC, checked against a bitwise reference written from the definition."""

from __future__ import annotations

import struct

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from deploy.body.unitree_lowlevel import (
    LOWCMD_STRUCT,
    LOWSTATE_STRUCT,
    NUM_MOTOR_SLOTS,
    LowCmdFrame,
    LowStateFrame,
    make_lowcmd,
    unitree_crc32,
)


def reference_crc(buffer: bytes) -> int:
    """The robot's CRC, bit by bit: little-endian uint32 words (without the crc word), MSB first, poly 0x04C11DB7,
    init 0xFFFFFFFF; per bit: shift left, xor poly if the top bit was set, xor poly again if the data bit is set."""
    words = struct.unpack(f"<{len(buffer) // 4}I", buffer)[:-1]
    crc = 0xFFFFFFFF
    for word in words:
        for bit in range(31, -1, -1):
            top = crc & 0x80000000
            crc = (crc << 1) & 0xFFFFFFFF
            if top:
                crc ^= 0x04C11DB7
            if (word >> bit) & 1:
                crc ^= 0x04C11DB7
    return crc


def test_layout_sizes_for_35_motors():
    assert NUM_MOTOR_SLOTS == 35
    assert LOWCMD_STRUCT.size == 4 + 35 * 28 + 5 * 4 == 1004
    assert LOWSTATE_STRUCT.size == 16 + 56 + 35 * 56 + 40 + 20 == 2092
    assert len(LowCmdFrame().pack()) == 1004 and len(LowStateFrame().pack()) == 2092


def test_crc_matches_the_bitwise_reference_on_a_command():
    rng = np.random.default_rng(1)
    frame = make_lowcmd(rng.normal(size=29), rng.normal(size=29), rng.uniform(0, 150, 29), rng.uniform(0, 4, 29),
                        rng.normal(size=29), mode_machine=5)
    assert frame.crc == reference_crc(frame.pack())
    assert frame.crc_ok()
    frame.q[3] += 0.01
    assert not frame.crc_ok()


def test_crc_of_known_patterns():
    zeros = bytes(1004)
    ones = bytes([0xFF]) * 1004
    assert unitree_crc32(zeros) == reference_crc(zeros)
    assert unitree_crc32(ones) == reference_crc(ones)
    assert unitree_crc32(zeros) != unitree_crc32(ones)


@settings(max_examples=25, deadline=None)
@given(st.binary(min_size=4, max_size=256).filter(lambda b: len(b) % 4 == 0))
def test_crc_matches_reference_on_random_buffers(buffer):
    assert unitree_crc32(buffer) == reference_crc(buffer)


def test_lowcmd_fields_land_at_their_offsets():
    frame = make_lowcmd(np.full(29, 0.5), np.zeros(29), np.full(29, 100.0), np.full(29, 2.0), np.zeros(29),
                        mode_machine=7, mode_pr=0)
    raw = frame.pack()
    assert raw[0] == 0 and raw[1] == 7 and raw[2:4] == b"\x00\x00"
    motor0 = struct.unpack_from("<B3x5fI", raw, 4)
    assert motor0 == (1, 0.5, 0.0, 0.0, 100.0, 2.0, 0)
    motor29 = struct.unpack_from("<B3x5fI", raw, 4 + 29 * 28)
    assert motor29[0] == 0  # unused slots stay disabled
    assert struct.unpack_from("<I", raw, 1000)[0] == frame.crc
    back = LowCmdFrame.unpack(raw)
    np.testing.assert_array_equal(back.q, frame.q)
    assert back.crc == frame.crc and back.mode_machine == 7


def test_lowstate_crc_round_trip():
    frame = LowStateFrame(mode_machine=5, tick=1234)
    frame.q[:29] = np.linspace(-1, 1, 29)
    frame.imu_quat_wxyz[:] = [0.9, 0.1, 0.2, 0.3]
    frame.wireless_remote[:4] = [1, 2, 3, 4]
    frame.with_crc()
    assert frame.crc == reference_crc(frame.pack())
    assert frame.crc_ok()
    frame.tick += 1
    assert not frame.crc_ok()

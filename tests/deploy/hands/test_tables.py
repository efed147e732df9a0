"""Register map and the value codecs of each transport."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.hands import tables
from deploy.hands.tables import REGISTERS


def test_addresses_and_sizes_from_the_manual():
    expect = {
        "HAND_ID": 1000,
        "CLEAR_ERROR": 1004,
        "ANGLE_SET": 1486,
        "FORCE_SET": 1498,
        "SPEED_SET": 1522,
        "ANGLE_ACT": 1546,
        "FORCE_ACT": 1582,
        "ERROR": 1606,
        "STATUS": 1612,
        "TEMP": 1618,
    }
    for name, address in expect.items():
        assert REGISTERS[name].address == address
    assert REGISTERS["ANGLE_SET"].element_address(3) == 1492
    assert REGISTERS["ERROR"].element_address(3) == 1609
    assert REGISTERS["ANGLE_ACT"].nbytes == 12 and REGISTERS["TEMP"].nbytes == 6
    assert not REGISTERS["ANGLE_ACT"].writable and REGISTERS["ANGLE_SET"].writable


def test_no_two_register_groups_overlap():
    spans = sorted((r.address, r.address + r.nbytes, r.name) for r in REGISTERS.values())
    for (_, end, a), (start, _, b) in zip(spans, spans[1:], strict=False):
        assert end <= start, f"{a} overlaps {b}"


def test_can_moves_only_the_documented_system_registers():
    assert REGISTERS["CLEAR_ERROR"].can_address == 4016
    assert REGISTERS["HAND_ID"].can_address == 250
    assert REGISTERS["ANGLE_SET"].can_address == 1486 and REGISTERS["ANGLE_ACT"].can_address == 1546


def test_state_blocks_are_contiguous():
    for block in tables.STATE_BLOCKS:
        tables.contiguous(block)
    with pytest.raises(ValueError, match="not adjacent"):
        tables.contiguous(("ANGLE_ACT", "ERROR"))


def test_little_endian_codec_round_trip_and_range_check():
    reg = REGISTERS["FORCE_ACT"]
    values = [-4000, -1, 0, 1, 1234, 4000]
    raw = tables.encode_values(reg, values)
    assert raw[:2] == (-4000).to_bytes(2, "little", signed=True)
    assert tables.decode_values(reg, raw).tolist() == values
    with pytest.raises(ValueError, match="takes 6 values"):
        tables.encode_values(reg, [1, 2])
    with pytest.raises(ValueError, match="does not fit"):
        tables.encode_values(REGISTERS["ERROR"], [256, 0, 0, 0, 0, 0])


def test_modbus_layouts():
    angle = REGISTERS["ANGLE_SET"]
    assert angle.modbus_layout == "i16" and angle.modbus_count == 6
    assert tables.encode_modbus(angle, [0, 1, 1000, 2, 3, 4])[2] == 1000
    force = REGISTERS["FORCE_ACT"]
    assert tables.decode_modbus(force, [0xFFFF, 0, 0, 0, 0, 0x8000 | 0x7060])[0] == -1
    err = REGISTERS["ERROR"]
    assert err.modbus_layout == "u8_pairs" and err.modbus_count == 3
    assert tables.encode_modbus(err, [1, 2, 3, 4, 5, 6]) == [0x0102, 0x0304, 0x0506]  # high byte first
    assert tables.decode_modbus(err, [0x0102, 0x0304, 0x0506]).tolist() == [1, 2, 3, 4, 5, 6]
    clear = REGISTERS["CLEAR_ERROR"]
    assert clear.modbus_layout == "u8" and tables.encode_modbus(clear, [1]) == [
        1
    ]  # as Unitree's SDK writes it
    with pytest.raises(ValueError):
        tables.decode_modbus(err, [1, 2])
    with pytest.raises(ValueError):
        tables.decode_modbus(angle, [70000] * 6)


def test_error_description_names_fingers_and_bits():
    text = tables.describe_errors(np.array([0, 0, 0, 1, 6, 0x20], dtype=np.uint8))
    assert "index: locked rotor" in text
    assert "thumb_bend: over-temperature+over-current" in text
    assert "thumb_rotate: unknown bits 0x20" in text
    assert tables.describe_errors([0] * 6) == ""

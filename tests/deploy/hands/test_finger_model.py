"""The simulated hand's finger model, on a hand-driven clock."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.hands import tables
from deploy.hands.finger_model import FULL_STROKE_S, FingerModel
from deploy.hands.sim_registers import DeviceRegisters


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def clock():
    return Clock()


def test_slews_toward_angle_set_at_speed_set_rate(clock):
    model = FingerModel(clock=clock)
    model.command(angle_set=[0] * 6, speed_set=[1000, 500, 250, 1000, 1000, 0])
    clock.t += FULL_STROKE_S / 2
    angles = model.measure()["ANGLE_ACT"]
    assert angles == [500, 750, 875, 500, 500, 1000]
    assert model.measure()["STATUS"][:3] == [tables.STATUS_GRASPING] * 3
    clock.t += 10
    m = model.measure()
    assert m["ANGLE_ACT"] == [0, 0, 0, 0, 0, 1000]
    assert m["STATUS"][0] == tables.STATUS_AT_TARGET and m["STATUS"][5] == tables.STATUS_GRASPING  # speed 0


def test_object_raises_force_and_force_set_stops_the_finger(clock):
    model = FingerModel(clock=clock)
    model.place_object([600, 600, None, 600, 600, 600], stiffness=10.0)
    model.command(angle_set=[0] * 6, force_set=[300, 800, 300, 300, 300, 300])
    clock.t += 5
    m = model.measure()
    assert m["ANGLE_ACT"][0] == 570 and m["FORCE_ACT"][0] == 300  # stops where 10 g/unit x 30 = FORCE_SET
    assert m["ANGLE_ACT"][1] == 520 and m["FORCE_ACT"][1] == 800
    assert m["ANGLE_ACT"][2] == 0 and m["FORCE_ACT"][2] == 0  # no object under the middle finger
    assert m["STATUS"][0] == tables.STATUS_AT_FORCE_LIMIT
    model.command(angle_set=[1000] * 6)
    clock.t += 5
    assert model.measure()["FORCE_ACT"] == [0] * 6


def test_error_bits_freeze_the_finger_until_cleared_and_sticky_bits_stay(clock):
    model = FingerModel(clock=clock)
    model.set_error_bits(tables.ERROR_LOCKED_ROTOR, fingers=[3])
    model.set_error_bits(tables.ERROR_OVER_TEMPERATURE, fingers=[4], sticky=True)
    model.command(angle_set=[0] * 6)
    clock.t += 1
    m = model.measure()
    assert m["ANGLE_ACT"][3] == 1000 and m["ERROR"][3] == 1 and m["STATUS"][3] == 255
    model.clear_errors()
    assert model.measure()["ERROR"] == [0, 0, 0, 0, 2, 0]
    model.release_sticky_errors()
    model.clear_errors()
    assert model.measure()["ERROR"] == [0] * 6


def test_minus_one_leaves_a_dof_alone(clock):
    model = FingerModel(clock=clock)
    model.command(angle_set=[200] * 6)
    model.command(angle_set=[-1, 300, -1, 300, -1, 300])
    assert model.commanded_angles.tolist() == [200, 300, 200, 300, 200, 300]


def test_external_physics_owns_the_measurement(clock):
    model = FingerModel(clock=clock)
    model.command(angle_set=[0] * 6)
    model.set_measured([100, 200, 300, 400, 500, 600], [5, 0, 0, 0, 0, -7])
    clock.t += 10
    m = model.measure()
    assert m["ANGLE_ACT"] == [100, 200, 300, 400, 500, 600] and m["FORCE_ACT"][5] == -7
    assert model.commanded_angles.tolist() == [0] * 6
    model.release_measured()
    clock.t += 10
    assert model.measure()["ANGLE_ACT"] == [0] * 6


def test_register_file_couples_writes_and_reads_to_the_model(clock):
    model = FingerModel(clock=clock)
    regs = DeviceRegisters(model, hand_id=3)
    assert regs.hand_id == 3
    angle_set = tables.REGISTERS["ANGLE_SET"]
    regs.write(angle_set.address, tables.encode_values(angle_set, [10, 20, 30, 40, 50, 60]))
    assert model.commanded_angles.tolist() == [10, 20, 30, 40, 50, 60]
    assert regs.writes[-1].register == "ANGLE_SET" and regs.writes[-1].values == (10, 20, 30, 40, 50, 60)
    clock.t += 10
    raw = regs.read(tables.REGISTERS["ANGLE_ACT"].address, 12)
    assert tables.decode_values(tables.REGISTERS["ANGLE_ACT"], raw).tolist() == [10, 20, 30, 40, 50, 60]
    # Modbus view of the same file: ERROR..TEMP as 9 registers, two u8 each, high byte first.
    model.set_error_bits(0x01, fingers=[0])
    words = regs.modbus_read(1606, 9)
    assert words[0] >> 8 == 0x01 and words[6] >> 8 == 32  # ERROR[0] and TEMP[0]
    assert regs.modbus_read(1558, 1) is None  # nothing documented there
    assert regs.modbus_write(1004, [1]) and model.measure()["ERROR"] == [0] * 6


def test_can_register_file_uses_the_moved_system_addresses(clock):
    model = FingerModel(clock=clock)
    model.set_error_bits(0x04)
    regs = DeviceRegisters(model, hand_id=1, can=True)
    regs.write(4016, b"\x01")  # CLEAR_ERROR on CAN firmware
    assert np.all(model.measure()["ERROR"] == np.zeros(6))
    assert regs.group_at(1004) is None

"""The simulated Inspire hands: the runtime's bytes move MuJoCo fingers; angles and forces come back as
register values (units 0..1000, grams)."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.hands.finger_model import FULL_STROKE_S
from sim2sim.clock import SimClock
from sim2sim.hands import GRAMS_PER_NEWTON, SimulatedInspireHands


class FakeFingerWorld:
    """The four world methods the hands use, with finger joints that jump to their targets (no dynamics)."""

    def __init__(self, open_rad, closed_rad):
        self.t = 0.0
        self.q = np.array(open_rad, dtype=float)
        self.forces = np.zeros(12)
        self.targets = None
        self.listeners = []

    def now(self) -> float:
        return self.t

    def hand_joint_pos(self):
        return self.q.copy()

    def finger_forces_n(self):
        return self.forces.copy()

    def set_hand_targets(self, rad):
        self.targets = np.array(rad)

    def add_listener(self, period_s, callback):
        self.listeners.append((period_s, callback))

    def step(self, seconds, dt):
        for _ in range(int(round(seconds / dt))):
            self.t += dt
            for _, cb in self.listeners:
                cb(self.t)


@pytest.fixture
def fake_hands(contract):
    from deploy.hand_units import HAND_SIDES, channel_arrays

    opens, closes = zip(*(channel_arrays(contract.hands[s]) for s in HAND_SIDES), strict=True)
    world = FakeFingerWorld(np.concatenate(opens), np.concatenate(closes))
    hands = SimulatedInspireHands(world, contract, world, rate_hz=100.0)  # the fake world is its own clock
    yield world, hands
    hands.close()


def test_bytes_move_the_fingers_at_the_device_speed(fake_hands):
    world, hands = fake_hands
    hands.hands.begin_cycle(np.array([0] * 6 + [1000] * 6))  # close the left hand over the serial protocol
    device = hands.devices[0]
    assert device.requests[("write", "ANGLE_SET")] >= 1  # real frames reached the device
    np.testing.assert_array_equal(hands.fingers["left"].commanded_angles, [0] * 6)
    world.step(0.3, 0.01)  # half of a full stroke at SPEED_SET 1000 (0.6 s)
    expected_units = 1000 - 0.3 / FULL_STROKE_S * 1000
    np.testing.assert_allclose(hands.setpoint[:6], expected_units, atol=1e-6)
    np.testing.assert_allclose(hands.setpoint[6:], 1000)
    rad = hands.closed_rad + hands.setpoint / 1000 * (hands.open_rad - hands.closed_rad)
    np.testing.assert_allclose(world.targets, rad)


def test_measured_angles_and_forces_come_back_as_registers(fake_hands, contract):
    world, hands = fake_hands
    world.q[:6] = hands.closed_rad[:6] + 0.25 * (hands.open_rad[:6] - hands.closed_rad[:6])  # left at 250 units
    world.forces[3] = 2.0  # 2 N on the left index
    world.step(0.01, 0.01)
    hands.hands.begin_cycle(None)
    reading = hands.hands.finish_cycle()
    np.testing.assert_array_equal(reading.angles[:6], [250] * 6)
    np.testing.assert_array_equal(reading.angles[6:], [1000] * 6)
    assert reading.forces[3] == round(2.0 * GRAMS_PER_NEWTON)  # grams, as FORCE_ACT
    assert reading.forces[3] == 204
    world.q[:6] = hands.open_rad[:6]  # the next physics update is what the next read reports
    world.step(0.01, 0.01)
    hands.hands.begin_cycle(None)
    np.testing.assert_array_equal(hands.hands.finish_cycle().angles[:6], [1000] * 6)


def test_force_limit_stops_closing(fake_hands):
    world, hands = fake_hands
    hands.hands.begin_cycle(np.array([0] * 12))
    world.step(0.1, 0.01)
    before = hands.setpoint.copy()
    world.forces[:] = 1000 / GRAMS_PER_NEWTON + 0.1  # every finger presses at FORCE_SET (1000 g)
    world.q[:] = hands.closed_rad + before / 1000 * (hands.open_rad - hands.closed_rad)
    world.step(0.2, 0.01)
    np.testing.assert_allclose(hands.setpoint, before, atol=1e-6)  # no further closing
    world.forces[:] = 0.0
    world.step(0.1, 0.01)
    assert np.all(hands.setpoint < before - 100)


def test_real_world_fingers_close(make_world, contract):
    world = make_world()
    clock = SimClock(world)
    hands = SimulatedInspireHands(world, contract, clock)
    try:
        hands.hands.begin_cycle(np.array([0, 0, 0, 0, 1000, 1000] + [1000] * 6))  # four left fingers
        world.advance_to(1.0)
        hands.hands.begin_cycle(None)
        reading = hands.hands.finish_cycle()
        assert np.all(reading.angles[:4] < 30)  # the MuJoCo joints reached the closed end
        assert np.all(reading.angles[4:] > 970)
        q = world.hand_joint_pos()
        np.testing.assert_allclose(q[:4], hands.closed_rad[:4], atol=0.06)
    finally:
        hands.close()


def test_pty_link_speaks_through_the_device_thread(make_world, contract):
    world = make_world()
    hands = SimulatedInspireHands(world, contract, SimClock(world), transport="serial", link="pty")
    try:
        hands.hands.begin_cycle(np.array([500] * 12))
        hands.hands.begin_cycle(None)
        reading = hands.hands.finish_cycle()
        assert not reading.faults
        np.testing.assert_array_equal(hands.commanded_units(), [500] * 12)
    finally:
        hands.close()
    with pytest.raises(ValueError, match="direct"):
        SimulatedInspireHands(world, contract, SimClock(world), transport="can", link="direct")

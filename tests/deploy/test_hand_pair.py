"""Two hands as the runtime uses them: unit conversion, threaded exchange, safe states, configuration."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.clock import FakeClock
from deploy.errors import DeployError
from deploy.hand_pair import Hands
from deploy.hand_units import HandChannel, rad_to_units, units_to_rad

from .conftest import FakeHandBus

CHANNELS = {
    side: [HandChannel(n, f"{side}_{n}", 0.0, 1.7) for n in ("pinky", "ring", "middle", "index")]
    + [HandChannel("thumb_bend", f"{side}_tb", 0.0, 0.5), HandChannel("thumb_rotate", f"{side}_tr", -0.1, 1.3)]
    for side in ("left", "right")
}


def make_hands(threaded=False, **kw):
    clock = FakeClock()
    left, right = FakeHandBus("left", clock), FakeHandBus("right", clock)
    hands = Hands(left, right, CHANNELS, clock=clock, threaded=threaded, **kw)
    hands.connect()
    return hands, left, right, clock


def test_units_mapping_matches_the_inspire_convention():
    open_rad, closed_rad = np.array([0.0, -0.1]), np.array([1.7, 1.3])
    np.testing.assert_allclose(units_to_rad([1000, 1000], open_rad, closed_rad), [0.0, -0.1])
    np.testing.assert_allclose(units_to_rad([0, 500], open_rad, closed_rad), [1.7, 0.6])
    np.testing.assert_array_equal(rad_to_units([0.85, 0.6], open_rad, closed_rad), [500, 500])
    np.testing.assert_array_equal(rad_to_units([-1.0, 5.0], open_rad, closed_rad), [1000, 0])  # clamped


def test_connect_clears_and_configures():
    hands, left, right, _ = make_hands(force_limits=[500] * 6, speeds=[800] * 6)
    for bus in (left, right):
        assert bus.clear_count == 1 and bus.configured == ([500] * 6, [800] * 6)
    reading = hands.finish_cycle()
    np.testing.assert_array_equal(reading.angles, [1000] * 12) and not reading.faults


@pytest.mark.parametrize("threaded", [False, True])
def test_exchange_writes_then_reads_back(threaded):
    hands, left, right, clock = make_hands(threaded=threaded)
    targets = np.arange(12) * 50
    hands.begin_cycle(targets)
    reading = hands.finish_cycle(wait_s=1.0)
    np.testing.assert_array_equal(left.writes[-1], targets[:6])
    np.testing.assert_array_equal(right.writes[-1], targets[6:])
    np.testing.assert_array_equal(reading.angles, targets)
    assert np.all(reading.stamps == clock.now())
    hands.close()


def test_safe_state_hold_resends_last_command_and_open_opens():
    hands, left, right, _ = make_hands()
    hands.begin_cycle(np.full(12, 300))
    hands.request_safe_state()
    hands.begin_cycle(None)
    np.testing.assert_array_equal(left.writes[-1], [300] * 6)
    assert len(left.writes) == 2
    hands.begin_cycle(None)
    assert len(left.writes) == 2  # read-only afterwards

    hands, left, right, _ = make_hands(safe_state="open")
    hands.begin_cycle(np.full(12, 300))
    hands.request_safe_state()
    hands.begin_cycle(None)
    np.testing.assert_array_equal(right.writes[-1], [1000] * 6)


def test_rejects_swapped_sides_and_bad_safe_state():
    clock = FakeClock()
    with pytest.raises(DeployError, match="left hand bus says it is the right hand"):
        Hands(FakeHandBus("right", clock), FakeHandBus("left", clock), CHANNELS, clock=clock)
    with pytest.raises(DeployError, match="safe state"):
        Hands(FakeHandBus("left", clock), FakeHandBus("right", clock), CHANNELS, clock=clock, safe_state="drop")


def test_threaded_exchange_still_running_is_reported_late():
    import threading

    hands, left, right, _ = make_hands(threaded=True)
    gate = threading.Event()
    original = left.read_state
    left.read_state = lambda: (gate.wait(2.0), original())[1]
    hands.begin_cycle(np.full(12, 200))
    reading = hands.finish_cycle(wait_s=0.0)
    assert hands.stats()["left"]["late_cycles"] == 1
    hands.begin_cycle(np.full(12, 400))  # skipped for the busy side, not queued
    gate.set()
    reading = hands.finish_cycle(wait_s=1.0)
    np.testing.assert_array_equal(left.writes[-1], [200] * 6)
    np.testing.assert_array_equal(reading.angles[6:], [400] * 6)
    hands.close()

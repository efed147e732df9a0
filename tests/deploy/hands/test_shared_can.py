"""Both hands on one CAN channel share one python-can Bus; replies are routed by hand id; every driver error is a
link fault. Includes an slcan USB adapter emulated on a pty, opened with python-can's own slcan interface."""

from __future__ import annotations

import can
import pytest

from deploy.errors import HandLinkError
from deploy.hands import make_hand_bus
from deploy.hands.shared_can import SharedCanBus
from deploy.hands.sim_slcan import SimulatedSlcanAdapter
from deploy.hands.simulated import start_simulated_hand

SLCAN_FAST_OPEN = {"sleep_after_open": 0.0}  # python-can waits 2 s after opening an slcan port by default


@pytest.fixture
def two_hands():
    """Two simulated hands (ids 1, 2) on one virtual channel; yields (left_sim, right_sim)."""
    left = start_simulated_hand("can", "left", hand_id=1, pace=False)
    right = start_simulated_hand("can", "right", hand_id=2, channel=left.channel, pace=False)
    yield left, right
    left.stop()
    right.stop()


@pytest.fixture
def slcan(two_hands):
    adapter = SimulatedSlcanAdapter(two_hands[0].channel)
    buses = [make_hand_bus("can", side, can_interface="slcan", can_channel=adapter.port, hand_id=i + 1,
                           timeout=0.3, bus_options=SLCAN_FAST_OPEN) for i, side in enumerate(("left", "right"))]
    yield adapter, buses
    for bus in buses:
        bus.disconnect()
    adapter.stop()


def shared_buses():
    return list(SharedCanBus._registry.values())


def test_two_hands_over_one_slcan_adapter_share_one_bus(slcan, two_hands):
    adapter, (left, right) = slcan
    left.connect()
    right.connect()
    assert len(shared_buses()) == 1 and sorted(shared_buses()[0].queues) == [1, 2]
    for _ in range(5):
        left.write_angles([100] * 6)
        right.write_angles([900] * 6)
        assert left.read_state().angles.shape == (6,) and right.read_state().angles.shape == (6,)
    assert two_hands[0].model.commanded_angles.tolist() == [100] * 6
    assert two_hands[1].model.commanded_angles.tolist() == [900] * 6
    assert adapter.commands.count("S8") == 1  # one python-can Bus (it sets the bit rate once) for both hands
    assert left.stats.link_errors == right.stats.link_errors == 0


def test_garbled_slcan_stream_is_a_link_fault_that_recovers(slcan):
    adapter, (left, right) = slcan
    left.connect()
    right.connect()
    adapter.garble_next(1)  # python-can's slcan parser raises ValueError on this line
    state = left.read_state()  # the try fails as "disconnected", the shared bus reopens, the retry succeeds
    assert state.angles.shape == (6,)
    assert left.stats.failures["disconnected"] >= 1 and left.stats.reconnects >= 1
    assert right.read_state().angles.shape == (6,)
    assert adapter.commands.count("S8") == 2  # reopened once, for both hands


def test_unplugged_slcan_adapter_raises_hand_link_error(slcan):
    adapter, (left, _) = slcan
    left.connect()
    adapter.unplug()
    with pytest.raises(HandLinkError, match="left hand"):
        left.read_state()


@pytest.mark.parametrize("error", [can.CanOperationError("bus off"), can.CanInitializationError("gone"),
                                   ValueError("garbled"), IndexError("short line"), OSError(5, "EIO"),
                                   TypeError("driver bug")])
def test_every_driver_error_is_a_link_fault(two_hands, monkeypatch, error):
    bus = make_hand_bus("can", "left", **two_hands[0].bus_kwargs(), timeout=0.2, retries=0)
    bus.connect()
    try:
        shared = shared_buses()[0]
        failing = {"n": 1}
        real_recv = shared._bus.recv

        def recv(timeout=None):
            if failing["n"]:
                failing["n"] -= 1
                raise error
            return real_recv(timeout)

        monkeypatch.setattr(shared._bus, "recv", recv)
        with pytest.raises(HandLinkError, match=type(error).__name__):
            bus.read_state()
        assert bus.read_state().angles.shape == (6,)  # the next request reopens the shared bus
    finally:
        bus.disconnect()


def test_same_hand_id_twice_on_a_channel_is_refused(two_hands):
    from deploy.errors import DeployError

    first = make_hand_bus("can", "left", **two_hands[0].bus_kwargs(), timeout=0.2)
    second = make_hand_bus("can", "right", **two_hands[0].bus_kwargs(), timeout=0.2)  # same id 1
    first.connect()
    try:
        with pytest.raises(DeployError, match="already attached"):
            second.connect()
    finally:
        first.disconnect()
    assert shared_buses() == []

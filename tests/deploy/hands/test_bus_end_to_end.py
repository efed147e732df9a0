"""Each transport end to end against its simulated device speaking the real bytes."""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from deploy.errors import DeployError, HandLinkError
from deploy.hands import make_hand_bus, tables
from deploy.hands.base import HandBus
from deploy.hands.simulated import start_simulated_hand


def test_write_angles_read_back_and_the_model_moves(hand_rig, transport):
    sim, bus, clock = hand_rig(transport)
    assert isinstance(bus, HandBus) and not bus.is_connected
    bus.connect()
    assert bus.is_connected
    first = bus.read_state()
    assert first.angles.tolist() == [1000] * 6 and first.status.tolist() == [tables.STATUS_AT_TARGET] * 6
    assert first.temperatures.tolist() == [32] * 6 and first.errors.dtype == np.uint8
    target = [0, 100, 250, 500, 750, 1000]
    bus.write_angles(target)
    assert sim.model.commanded_angles.tolist() == target
    clock.advance(0.3)  # 1000 units per 0.6 s at SPEED_SET 1000
    halfway = bus.read_state()
    assert halfway.angles.tolist() == [500, 500, 500, 500, 750, 1000]
    assert halfway.status[0] == tables.STATUS_GRASPING
    clock.advance(1.0)
    done = bus.read_state()
    assert done.angles.tolist() == target
    assert done.status.tolist() == [tables.STATUS_AT_TARGET] * 6
    assert done.stamp >= halfway.stamp and abs(done.stamp - time.monotonic()) < 1.0
    frames_per_group = 2 if transport == "can" else 1  # CAN: 12 bytes = 8 + 4
    assert sim.requests[("write", "ANGLE_SET")] == frames_per_group
    assert sim.requests[("read", "ANGLE_ACT")] == 4 * frames_per_group  # connect's probe + three state reads


def test_configure_sets_force_and_speed_registers(hand_rig, transport):
    sim, bus, clock = hand_rig(transport)
    bus.connect()
    bus.configure([300, 400, 500, 600, 700, 3000], [500, 500, 500, 500, 500, 1000])
    assert sim.model.force_set.tolist() == [300, 400, 500, 600, 700, 3000]
    assert sim.model.speed_set.tolist() == [500] * 5 + [1000]
    written = {(w.register, w.values) for w in sim.writes}
    if transport == "can":  # 12 bytes travel as 8 + 4
        assert ("FORCE_SET", (300, 400, 500, 600)) in written and ("FORCE_SET", (700, 3000)) in written
    else:
        assert ("FORCE_SET", (300, 400, 500, 600, 700, 3000)) in written
    bus.write_angles([0] * 6)
    clock.advance(0.3)
    assert bus.read_state().angles.tolist() == [750] * 5 + [500]  # half speed moved half as far


def test_force_rises_on_an_object_and_force_set_stops_the_finger(hand_rig, transport):
    sim, bus, clock = hand_rig(transport)
    bus.connect()
    bus.configure([300] * 6, [1000] * 6)
    sim.model.place_object([600, 600, 600, None, None, None], stiffness=10.0)
    bus.write_angles([0] * 6)
    clock.advance(2.0)
    state = bus.read_state()
    assert state.angles.tolist() == [570, 570, 570, 0, 0, 0]
    assert state.forces.tolist() == [300, 300, 300, 0, 0, 0]
    assert state.status.tolist()[:3] == [tables.STATUS_AT_FORCE_LIMIT] * 3


def test_two_hands_on_distinct_ids_and_links(hand_rig, transport):
    if transport == "can":  # both hands on one CAN bus, told apart by id
        left_sim, left, _ = hand_rig("can", "left", hand_id=1)
        right_sim = start_simulated_hand("can", "right", hand_id=2, channel=left_sim.channel, pace=False)
        right = make_hand_bus("can", "right", timeout=0.1, **right_sim.bus_kwargs())
        assert right_sim.channel == left_sim.channel
    else:
        left_sim, left, _ = hand_rig(transport, "left", hand_id=1)
        right_sim, right, _ = hand_rig(transport, "right", hand_id=2)
        assert left_sim.port != right_sim.port
    try:
        left.connect()
        right.connect()
        left.write_angles([100] * 6)
        right.write_angles([900] * 6)
        assert left_sim.model.commanded_angles.tolist() == [100] * 6
        assert right_sim.model.commanded_angles.tolist() == [900] * 6
        frames_per_group = 2 if transport == "can" else 1
        assert left_sim.requests[("write", "ANGLE_SET")] == frames_per_group
        assert right_sim.requests[("write", "ANGLE_SET")] == frames_per_group
        assert left.read_state().angles.shape == (6,) and right.read_state().angles.shape == (6,)
    finally:
        if transport == "can":
            right.disconnect()
            right_sim.stop()


@pytest.mark.parametrize("transport_name", ["serial", "modbus"])
def test_rs485_adapter_echo(hand_rig, transport_name):
    options = {"handle_local_echo": True} if transport_name == "modbus" else {}
    sim, bus, clock = hand_rig(transport_name, echo=True, bus_options=options)
    bus.connect()
    bus.write_angles([250] * 6)
    clock.advance(1.0)
    assert bus.read_state().angles.tolist() == [250] * 6
    assert bus.stats.retries == 0


def test_clamps_before_anything_goes_on_the_wire(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    bus.write_angles([-500, 1500, 2000.7, -1, 999.6, 0.4])
    assert sim.model.commanded_angles.tolist() == [0, 1000, 1000, 0, 1000, 0]
    assert bus.last_command.tolist() == [0, 1000, 1000, 0, 1000, 0]
    with pytest.raises(ValueError, match="finite"):
        bus.write_angles([float("nan")] * 6)
    with pytest.raises(ValueError, match="6 values"):
        bus.write_angles([500] * 5)
    with pytest.raises(DeployError, match="FORCE_SET"):
        bus.configure([3001] * 6, [1000] * 6)
    with pytest.raises(DeployError, match="SPEED_SET"):
        bus.configure([1000] * 6, [-5] * 6)
    angle_writes = [w for w in sim.writes if w.register == "ANGLE_SET"]
    assert angle_writes and all(0 <= v <= 1000 for w in angle_writes for v in w.values)


@pytest.mark.parametrize("transport_name", ["serial", "modbus", "can"])
def test_random_commands_never_leave_0_to_1000_on_the_wire(hand_rig, transport_name):
    sim, bus, _ = hand_rig(transport_name)
    bus.connect()

    @settings(max_examples=40, deadline=None, database=None)
    @given(st.lists(st.floats(-1e6, 1e6), min_size=6, max_size=6))
    def check(units):
        before = len(sim.writes)
        bus.write_angles(units)
        new = [w for w in sim.writes[before:] if w.register == "ANGLE_SET"]
        assert new and all(0 <= v <= 1000 for w in new for v in w.values)

    check()


def test_not_connected_is_a_link_error_and_bad_ports_are_user_errors(tmp_path):
    bus = make_hand_bus("serial", "left", port=str(tmp_path / "ttyUSB9"))
    with pytest.raises(HandLinkError, match="not connected"):
        bus.read_state()
    with pytest.raises(DeployError, match="cannot open"):
        bus.connect()
    assert not bus.is_connected
    modbus = make_hand_bus("modbus", "left", port=str(tmp_path / "ttyUSB9"))
    with pytest.raises(DeployError, match="cannot open"):
        modbus.connect()
    can_bus = make_hand_bus("can", "left", can_channel="can0", can_interface="no-such-interface")
    with pytest.raises(DeployError, match="cannot open"):
        can_bus.connect()


@pytest.mark.parametrize(
    ("args", "kwargs", "message"),
    [
        (("rs232", "left"), {"port": "/dev/null"}, "unknown hand transport"),
        (("serial", "middle"), {"port": "/dev/null"}, "side"),
        (("serial", "left"), {}, "needs a port"),
        (("can", "left"), {}, "needs can_channel"),
        (("serial", "left"), {"port": "/dev/null", "hand_id": 0}, "hand id"),
        (("modbus", "left"), {"port": "/dev/null", "hand_id": 248}, "hand id"),
        (("serial", "left"), {"port": "/dev/null", "retries": -1}, "retries"),
        (("serial", "left"), {"port": "/dev/null", "timeout": 0}, "timeout"),
        (("serial", "left"), {"port": "/dev/null", "safe_pose": "drop"}, "safe pose"),
        (("serial", "left"), {"port": "/dev/null", "safe_pose": [1200] * 6}, "safe pose"),
    ],
)
def test_factory_rejects_bad_settings(args, kwargs, message):
    with pytest.raises(DeployError, match=message):
        make_hand_bus(*args, **kwargs)


def test_connect_fails_cleanly_when_the_hand_is_silent(hand_rig, transport):
    sim, bus, _ = hand_rig(transport, retries=1)
    sim.drop_next(10 if transport == "can" else 2)  # CAN drops per frame (2 per ANGLE_ACT read)
    with pytest.raises(HandLinkError, match="read ANGLE_ACT failed after 2 tries"):
        bus.connect()
    assert not bus.is_connected


def test_disconnect_applies_the_safe_pose(hand_rig, transport):
    sim, hold_bus, _ = hand_rig(transport)
    hold_bus.connect()
    hold_bus.write_angles([300] * 6)
    hold_bus.disconnect()  # "hold": the last command goes out again, nothing opens
    assert not hold_bus.is_connected
    last = [w for w in sim.writes if w.register == "ANGLE_SET"][-1]
    assert set(last.values) == {300}
    assert sim.requests[("write", "ANGLE_SET")] == (4 if transport == "can" else 2)
    open_sim, open_bus, _ = hand_rig(transport, safe_pose="open")
    open_bus.connect()
    open_bus.write_angles([300] * 6)
    open_bus.disconnect()
    assert open_sim.model.commanded_angles.tolist() == [1000] * 6


def test_state_cache_keeps_values_and_ages(hand_rig, transport):
    sim, bus, clock = hand_rig(transport, retries=0)
    bus.connect()
    assert bus.last_state is None  # connect only probed ANGLE_ACT
    state = bus.read_state()
    cached = bus.last_state
    assert cached is not None and cached.angles.tolist() == state.angles.tolist()
    assert 0 <= bus.cache_age("ANGLE_ACT") < 1.0 and bus.cache_age("CURRENT") == float("inf")
    sim.drop_next(10)
    with pytest.raises(HandLinkError):
        bus.read_state()
    assert bus.last_state.angles.tolist() == state.angles.tolist()  # last known values survive a failure
    assert bus.cached("FORCE_ACT").values.tolist() == state.forces.tolist()


def test_replies_are_paced_at_the_line_rate(hand_rig):
    sim, bus, _ = hand_rig("serial", pace=True)
    bus.connect()
    start = time.monotonic()
    for _ in range(5):
        bus.read_state()
    elapsed = time.monotonic() - start
    wire = 5 * (9 + 20 + 9 + 20 + 9 + 26) * 10 / 115200  # three reads per state, request + reply bytes
    assert elapsed >= wire * 0.99
    assert sim.wire_bits >= 5 * (9 + 20 + 9 + 20 + 9 + 26) * 10


def test_rate_bench_runs_and_ends_with_its_summary_line(capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[3] / "bench" / "hand_bus_rate.py"
    spec = importlib.util.spec_from_file_location("hand_bus_rate", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--seconds", "0.1", "--repeats", "1", "--transports", "serial", "can"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    ratio = float(lines[-1].removeprefix("hand_bus_rate: "))
    assert lines[-1].startswith("hand_bus_rate: ") and 0.0 < ratio <= 1.0  # paced hands: never beats the line

"""Fault injection on every transport: the right exception after the configured tries, and recovery.

The probes are one request and one reply on every transport (on CAN too: TEMP is 6 bytes, CLEAR_ERROR 1), so
"the next n replies" means the same thing everywhere.
"""

from __future__ import annotations

import logging

import pytest

from deploy.errors import HandFaultError, HandLinkError
from deploy.hands import tables

CHECKSUM_KIND = {"serial": "checksum", "modbus": "checksum", "can": "error_frame"}


def probe_read(bus):
    return bus.read_register("TEMP")


@pytest.mark.parametrize("retries", [0, 2, 4])
def test_silence_raises_link_error_after_exactly_the_configured_tries(hand_rig, transport, retries):
    sim, bus, _ = hand_rig(transport, retries=retries)
    bus.connect()
    before = sim.requests[("read", "TEMP")]
    sim.drop_next(retries + 1)
    with pytest.raises(HandLinkError) as info:
        probe_read(bus)
    tries = retries + 1
    message = str(info.value)
    assert f"after {tries} {'try' if tries == 1 else 'tries'}" in message
    assert "right hand" in message and "id 1" in message and "TEMP" in message and "timeout" in message
    assert sim.requests[("read", "TEMP")] - before == tries  # every try reached the device
    assert bus.stats.failures["timeout"] == tries and bus.stats.link_errors == 1
    assert probe_read(bus).tolist() == [32] * 6  # the next call works again


def test_one_lost_reply_is_absorbed_by_a_retry(hand_rig, transport, caplog):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    sim.drop_next(1)
    with caplog.at_level(logging.DEBUG, logger="deploy.hands"):
        bus.clear_errors()
    assert any("write CLEAR_ERROR, try 1/3 failed: timeout" in r.getMessage() for r in caplog.records)
    assert bus.stats.retries == 1 and bus.stats.failures["timeout"] == 1 and bus.stats.link_errors == 0
    assert sim.requests[("write", "CLEAR_ERROR")] == 2


def test_bad_checksum(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    sim.corrupt_checksum_next(1)
    assert probe_read(bus).tolist() == [32] * 6
    assert bus.stats.failures[CHECKSUM_KIND[transport]] == 1
    sim.corrupt_checksum_next(3)
    with pytest.raises(HandLinkError, match=f"TEMP failed after 3 tries \\(last: {CHECKSUM_KIND[transport]}"):
        probe_read(bus)


def test_garbled_reply(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    sim.garble_next(3)
    with pytest.raises(HandLinkError, match="CLEAR_ERROR failed after 3 tries \\(last: garbled"):
        bus.clear_errors()
    assert sim.faults_applied["garble"] == 3
    bus.clear_errors()


def test_partial_reply(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    sim.partial_next(3)
    with pytest.raises(HandLinkError, match="TEMP failed after 3 tries \\(last: partial"):
        probe_read(bus)
    sim.partial_next(1)
    assert probe_read(bus).tolist() == [32] * 6


def test_noise_before_a_good_reply(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    sim.noise_before_next(1)
    assert probe_read(bus).tolist() == [32] * 6
    if transport != "modbus":  # our parsers resync; pymodbus' RTU framer may drop the buffer and need a retry
        assert bus.stats.retries == 0


def test_disconnect_then_reconnect(hand_rig, transport):
    sim, bus, clock = hand_rig(transport)
    bus.connect()
    bus.write_angles([400] * 6)
    sim.disconnect()
    with pytest.raises(HandLinkError, match="after 3 tries") as info:
        bus.read_state()
    expected = "timeout" if transport == "can" else "disconnected"  # a CAN hand falls silent; a pty vanishes
    assert f"last: {expected}" in str(info.value)
    sim.reconnect()
    clock.advance(1.0)
    assert bus.read_state().angles.tolist() == [400] * 6  # the bus reopens the link by itself
    if transport != "can":
        assert bus.stats.reconnects >= 1


def test_explicit_reconnect(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    sim.disconnect()
    with pytest.raises(HandLinkError):  # not DeployError: the port existed, the hardware went away
        bus.reconnect()
    assert not bus.is_connected
    sim.reconnect()
    bus.reconnect()
    assert bus.is_connected and bus.read_state().angles.tolist() == [1000] * 6


def test_device_error_bits_raise_a_fault_with_the_state(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    before = sim.total_requests
    sim.set_error_bits(tables.ERROR_LOCKED_ROTOR, fingers=[3])
    with pytest.raises(HandFaultError) as info:
        bus.read_state()
    message = str(info.value)
    assert (
        "right hand" in message
        and "id 1" in message
        and "ERROR" in message
        and "index: locked rotor" in message
    )
    assert info.value.state.errors.tolist() == [0, 0, 0, 1, 0, 0]
    assert info.value.state.angles.tolist() == [1000] * 6
    per_state = 7 if transport == "can" else 3
    assert sim.total_requests - before == per_state  # a fault is reported, never retried
    assert bus.stats.fault_errors == 1
    bus.clear_errors()
    assert not bus.read_state().has_fault
    sim.set_error_bits(tables.ERROR_OVER_TEMPERATURE, fingers=[0], sticky=True)
    bus.clear_errors()
    with pytest.raises(HandFaultError, match="pinky: over-temperature"):
        bus.read_state()  # still hot: CLEAR_ERROR cannot clear it
    sim.model.release_sticky_errors()
    bus.clear_errors()
    assert not bus.read_state().has_fault


def test_a_refused_write_is_a_device_fault_and_not_retried(hand_rig, transport):
    sim, bus, _ = hand_rig(transport)
    bus.connect()
    sim.refuse_writes_next(1)
    expected = "Modbus exception 4" if transport == "modbus" else "hand refused the write to CLEAR_ERROR"
    with pytest.raises(HandFaultError, match=expected) as info:
        bus.clear_errors()
    assert (
        "right hand" in str(info.value) and "id 1" in str(info.value) and "on try 1 of 3" in str(info.value)
    )
    assert sim.requests[("write", "CLEAR_ERROR")] == 1 and bus.stats.retries == 0
    bus.write_angles([123] * 6)
    assert sim.model.commanded_angles.tolist() == [123] * 6


def test_can_error_frames_are_counted_and_retried(hand_rig):
    sim, bus, _ = hand_rig("can")
    bus.connect()
    sim.error_frame_next(1)
    bus.clear_errors()
    assert bus.error_frames == 1 and bus.stats.failures["error_frame"] == 1
    sim.error_frame_next(3)
    with pytest.raises(HandLinkError, match="CLEAR_ERROR failed after 3 tries \\(last: error_frame"):
        bus.clear_errors()
    assert bus.error_frames == 4
    sim.send_error_frame()  # a stray error frame between requests does not fail the next one
    bus.clear_errors()


def test_can_chunked_read_survives_a_lost_chunk(hand_rig):
    sim, bus, _ = hand_rig("can", bus_options={"chunk_bytes": 2})
    bus.connect()
    sim.drop_next(1)
    state = bus.read_state()  # 6 + 6 + 3 frames, one reply lost: the whole state is asked again once
    assert state.angles.tolist() == [1000] * 6 and bus.stats.retries == 1
    assert sim.requests[("read", "ANGLE_ACT")] == 6 * 3  # probe, failed try, good try; 2-byte reads


def test_can_without_pipelining(hand_rig):
    sim, bus, clock = hand_rig("can", bus_options={"pipeline": False})
    bus.connect()
    bus.write_angles([10] * 6)
    clock.advance(2.0)
    assert bus.read_state().angles.tolist() == [10] * 6


def test_modbus_exception_reply_is_a_device_fault(hand_rig):
    sim, bus, _ = hand_rig("modbus")
    bus.connect()
    sim.exception_next(1)
    with pytest.raises(HandFaultError, match="Modbus exception 4 \\(slave device failure\\)"):
        bus.write_angles([500] * 6)
    assert bus.stats.attempts == bus.stats.requests  # not retried
    bus.write_angles([500] * 6)

"""CAN identifiers, chunking and reply matching, with a property test over random frames."""

from __future__ import annotations

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deploy.hands import can_frames
from deploy.hands.can_frames import (
    RW_READ,
    RW_WRITE,
    Pending,
    classify_reply,
    make_id,
    parse_id,
    parse_request,
)
from deploy.hands.tables import REGISTERS


def test_identifier_examples_from_the_notes():
    assert make_id(RW_READ, 1552, 1) == 0x01840001  # read ANGLE_ACT(3)
    assert make_id(RW_WRITE, 1492, 1) == 0x05750001  # write ANGLE_SET(3)
    assert make_id(RW_WRITE, 1486, 1) == 0x05738001  # write ANGLE_SET(0)
    assert parse_id(0x05750001) == can_frames.CanId(RW_WRITE, 1492, 1)
    assert parse_id(1 << 29) is None and parse_id(2 << 26) is None
    with pytest.raises(ValueError):
        make_id(RW_READ, 4096, 1)
    with pytest.raises(ValueError):
        make_id(RW_READ, 1546, 1 << 14)


def test_write_of_angle_set_3_matches_the_notes_data():
    msg = Pending(RW_WRITE, 1492, 1, (600).to_bytes(2, "little")).message
    assert (
        msg.arbitration_id == 0x05750001 and msg.is_extended_id and bytes(msg.data) == bytes.fromhex("58 02")
    )


def test_chunks_never_straddle_groups_and_respect_element_size():
    assert can_frames.chunks(REGISTERS["ANGLE_ACT"], 1546) == [(1546, 8), (1554, 4)]
    assert can_frames.chunks(REGISTERS["ERROR"], 1606) == [(1606, 6)]
    assert can_frames.chunks(REGISTERS["ANGLE_SET"], 1486, chunk_bytes=2) == [
        (1486 + 2 * i, 2) for i in range(6)
    ]
    assert can_frames.chunks(REGISTERS["CLEAR_ERROR"], 4016) == [(4016, 1)]


def test_frame_bits():
    assert can_frames.frame_bits(0) == 67 and can_frames.frame_bits(8) == 131


def test_reply_classification():
    read = Pending(RW_READ, 1546, 1, b"\x08")
    good = can.Message(arbitration_id=read.arbitration_id, is_extended_id=True, data=bytes(8))
    assert classify_reply(good, read) == "ok"
    short = can.Message(arbitration_id=read.arbitration_id, is_extended_id=True, data=bytes(3))
    assert classify_reply(short, read) == "partial"
    other = can.Message(arbitration_id=read.arbitration_id + 1, is_extended_id=True, data=bytes(8))
    assert classify_reply(other, read) == "unrelated"
    assert classify_reply(can.Message(is_error_frame=True), read) == "error_frame"
    write = Pending(RW_WRITE, 1486, 1, bytes(8))
    for ack in (b"", b"\x01"):
        assert classify_reply(can.Message(arbitration_id=write.arbitration_id, data=ack), write) == "ok"
    assert (
        classify_reply(can.Message(arbitration_id=write.arbitration_id, data=b"\x01\x02"), write) == "garbled"
    )


def test_device_side_request_parsing():
    req = Pending(RW_READ, 1546, 7, b"\x08").message
    assert parse_request(req, 7) == (RW_READ, 1546, b"\x08")
    assert parse_request(req, 8) is None  # another hand
    bad_len = can.Message(arbitration_id=make_id(RW_READ, 1546, 7), data=b"\x09")
    assert parse_request(bad_len, 7) is None


def message_from_bytes(raw: bytes) -> can.Message:
    """Any 4+1+n random bytes -> a CAN message (id, flags, data)."""
    head = raw[:5].ljust(5, b"\x00")
    flags = head[4]
    ident = int.from_bytes(head[:4], "little") & (0x1FFFFFFF if flags & 1 else 0x7FF)
    return can.Message(
        arbitration_id=ident,
        is_extended_id=bool(flags & 1),
        is_error_frame=bool(flags & 2),
        is_remote_frame=bool(flags & 4 and not flags & 2),
        data=raw[5:13],
    )


# Requests the bus may be waiting on: every state chunk and both write kinds, hand 1.
PENDING = [
    Pending(RW_READ, a, 1, bytes([n]))
    for name in ("ANGLE_ACT", "FORCE_ACT", "ERROR", "STATUS", "TEMP")
    for a, n in can_frames.chunks(REGISTERS[name], REGISTERS[name].can_address)
] + [Pending(RW_WRITE, 1486, 1, bytes(8)), Pending(RW_WRITE, 4016, 1, b"\x01")]


@pytest.mark.slow
@settings(max_examples=10_000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=14))
def test_can_decoding_never_crashes_and_accepts_only_exact_replies(raw):
    msg = message_from_bytes(raw)
    for pending in PENDING:
        verdict = classify_reply(msg, pending)
        assert verdict in ("ok", "error_frame", "partial", "garbled", "unrelated")
        if verdict == "ok":
            assert msg.is_extended_id and not msg.is_error_frame and not msg.is_remote_frame
            assert msg.arbitration_id == pending.arbitration_id
            want = pending.reply_length
            assert len(msg.data) == want if want is not None else len(msg.data) <= 1
    request = parse_request(msg, 1)
    if request is not None:
        rw, address, data = request
        assert make_id(rw, address, 1) == msg.arbitration_id and 1 <= len(data) <= 8

"""Vendor RS485 frames: the protocol notes' worked examples byte for byte, and the streaming parser."""

from __future__ import annotations

import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deploy.hands import frames
from deploy.hands.frames import REPLY_HEADER, REQUEST_HEADER, FrameParser


def hx(text: str) -> bytes:
    return bytes.fromhex(text)


def test_worked_examples_from_the_protocol_notes():
    assert frames.encode_read(1, 1546, 12) == hx("EB 90 01 04 11 0A 06 0C 32")
    assert frames.encode_read(1, 1582, 12) == hx("EB 90 01 04 11 2E 06 0C 56")
    assert frames.encode_read(1, 1606, 18) == hx("EB 90 01 04 11 46 06 12 74")
    all_open = struct.pack("<6h", *[1000] * 6)
    assert frames.encode_write(1, 1486, all_open) == hx(
        "EB 90 01 0F 12 CE 05 E8 03 E8 03 E8 03 E8 03 E8 03 E8 03 77"
    )
    manual = frames.encode_write(1, 1486, struct.pack("<6h", 100, 100, 100, 100, 2000, 0))
    assert len(manual) == 20 and manual[-1] == 0x5C
    assert frames.encode_write_ack(1, 1486) == hx("90 EB 01 04 12 CE 05 01 EB")
    assert frames.encode_write(1, 1004, b"\x01") == hx("EB 90 01 04 12 EC 03 01 07")
    change_id = frames.encode_write(1, 1000, b"\x02")
    assert change_id[:8] == hx("EB 90 01 04 12 E8 03 02") and change_id[8] == frames.checksum(change_id[2:8])


def test_frame_sizes_match_the_notes():
    assert frames.READ_REQUEST_SIZE == 9 and frames.WRITE_ACK_SIZE == 9
    assert frames.read_reply_size(12) == 20
    assert frames.write_request_size(12) == 20


def test_parser_decodes_a_reply_fed_byte_by_byte():
    reply = frames.encode_read_reply(3, 1546, bytes(range(12)))
    parser = FrameParser(REPLY_HEADER)
    out = []
    for b in reply:
        out += parser.feed(bytes([b]))
    assert len(out) == 1
    frame = out[0]
    assert (frame.hand_id, frame.cmd, frame.address, frame.payload) == (
        3,
        frames.CMD_READ,
        1546,
        bytes(range(12)),
    )
    assert parser.pending == 0 and parser.garbage_bytes == 0


def test_parser_rejects_bad_checksum_and_resyncs_on_the_next_frame():
    good = frames.encode_write_ack(1, 1486)
    bad = good[:-1] + bytes([good[-1] ^ 0x01])
    parser = FrameParser(REPLY_HEADER)
    assert parser.feed(bad) == []
    assert parser.bad_checksums == 1
    assert parser.feed(good) == [frames.Frame(REPLY_HEADER, 1, frames.CMD_WRITE, 1486, b"\x01")]


def test_a_stray_header_in_noise_does_not_swallow_the_real_reply():
    # "90 EB 05 F0" claims a 245-byte frame; the complete valid reply after it must still be found.
    good = frames.encode_read_reply(1, 1546, bytes(12))
    parser = FrameParser(REPLY_HEADER)
    assert parser.feed(b"\x90\xeb\x05\xf0junk" + good) == [
        frames.Frame(REPLY_HEADER, 1, frames.CMD_READ, 1546, bytes(12))
    ]


def test_partial_frame_waits_then_completes():
    good = frames.encode_read_reply(1, 1582, bytes(12))
    parser = FrameParser(REPLY_HEADER)
    assert parser.feed(good[:11]) == []
    assert parser.pending == 11
    assert len(parser.feed(good[11:])) == 1


def test_bad_length_byte_is_rejected():
    parser = FrameParser(REPLY_HEADER)
    assert parser.feed(b"\x90\xeb\x01\x02\x11\x00\x00\x00") == []  # LEN 2 < minimum 4
    assert parser.bad_lengths == 1


def test_requests_and_replies_use_different_headers():
    request = frames.encode_read(1, 1546, 12)
    assert FrameParser(REPLY_HEADER).feed(request) == []
    assert len(FrameParser(REQUEST_HEADER).feed(request)) == 1


# ------------------------------------------------------------------------------------------- property tests
# Maps a random byte to a header or length byte a third of the time, so streams are full of near-frames.
NEAR_FRAME = bytes((0x90, 0xEB, 0x04, 0x0F, 0x11, 0x12)[b % 6] if b % 3 == 0 else b for b in range(256))


def frames_among_noise(raw: bytes) -> bytes:
    """Deterministically turn random bytes into [noise, valid reply] pairs."""
    out, i = bytearray(), 0
    while i + 2 < len(raw):
        noise_len, payload_len = raw[i] % 8, 1 + raw[i + 1] % 20
        i += 2
        out += raw[i : i + noise_len]
        i += noise_len
        payload = raw[i : i + payload_len] or b"\x00"
        i += payload_len
        out += frames.encode_read_reply(raw[0], 1546, payload)
    return bytes(out)


def split_stream(raw: bytes) -> tuple[int, bytes, list[bytes]]:
    """One random blob -> (stream, chunks): byte 0 picks plain / near-frame / frames-in-noise, bytes 1-3 cut
    the stream into chunks. A single binary draw keeps 10 000 examples fast (hypothesis' own cost per draw
    dominates here)."""
    head, body = raw[:4].ljust(4, b"\x00"), raw[4:]
    mode = head[0] % 3
    stream = body if mode == 0 else body.translate(NEAR_FRAME) if mode == 1 else frames_among_noise(body)
    cuts = sorted(c % (len(stream) + 1) for c in head[1:])
    return mode, stream, [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]


PROPERTY = settings(
    max_examples=10_000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow]
)


@pytest.mark.slow
@PROPERTY
@given(st.binary(max_size=200))
def test_vendor_parser_never_crashes_and_never_accepts_a_bad_checksum(raw):
    mode, stream, chunks = split_stream(raw)
    parser = FrameParser(REPLY_HEADER)
    found = []
    for chunk in chunks:
        found += parser.feed(chunk)
    for frame in found:
        assert frame.header == REPLY_HEADER
        wire = frame.encode()  # recomputes the checksum: must equal the bytes that were on the wire
        assert wire in stream
        assert frames.MIN_LEN <= wire[3] <= frames.MAX_LEN
        assert wire[-1] == sum(wire[2:-1]) & 0xFF
    assert parser.pending <= len(stream)
    if mode == 2 and stream and b"\x90" not in raw[4:]:
        assert found  # frames in header-free noise are always found


@settings(max_examples=300, deadline=None, database=None)
@given(
    st.lists(st.tuples(st.binary(max_size=10), st.binary(min_size=1, max_size=24)), min_size=1, max_size=5)
)
def test_every_valid_frame_after_header_free_noise_is_recovered(parts):
    replies = [frames.encode_read_reply(1, 1546 + i, payload) for i, (_, payload) in enumerate(parts)]
    stream = b"".join(
        noise.replace(b"\x90", b"\x00") + reply for (noise, _), reply in zip(parts, replies, strict=True)
    )
    parser = FrameParser(REPLY_HEADER)
    assert [f.encode() for f in parser.feed(stream)] == replies

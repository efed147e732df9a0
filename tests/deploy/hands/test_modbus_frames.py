"""Modbus RTU reply decoding as the bus does it (pymodbus' RTU framer + our checks), against our own CRC."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deploy.hands.modbus_bus import diagnose_reply, parse_read_reply


def crc16_modbus(data: bytes) -> bytes:
    """Reference CRC-16/MODBUS (poly 0xA001 reflected, init 0xFFFF), low byte first on the wire."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc.to_bytes(2, "little")


def read_reply(device_id: int, words: list[int]) -> bytes:
    body = bytes([device_id, 0x03, 2 * len(words)]) + b"".join(w.to_bytes(2, "big") for w in words)
    return body + crc16_modbus(body)


def test_reference_crc_matches_the_standard_example():
    assert crc16_modbus(bytes.fromhex("01 03 00 00 00 0A")) == bytes.fromhex("C5 CD")


def test_good_reply_is_decoded():
    words = [1000, 0, 65535, 42, 7, 1]
    assert parse_read_reply(read_reply(1, words), 1, 6) == words


def test_bad_crc_wrong_id_and_wrong_count_are_rejected():
    good = read_reply(1, [1, 2, 3, 4, 5, 6])
    assert parse_read_reply(good[:-1] + bytes([good[-1] ^ 1]), 1, 6) is None
    assert parse_read_reply(read_reply(2, [1, 2, 3, 4, 5, 6]), 1, 6) is None
    assert parse_read_reply(good, 1, 9) is None
    assert parse_read_reply(good[:10], 1, 6) is None


def test_exception_reply_is_not_data():
    body = bytes([1, 0x83, 0x02])
    assert parse_read_reply(body + crc16_modbus(body), 1, 6) is None


def test_failure_diagnosis():
    good = read_reply(1, [1, 2, 3, 4, 5, 6])
    assert diagnose_reply(b"", 1, 3) == "timeout"
    assert diagnose_reply(good[:9], 1, 3) == "partial"
    assert diagnose_reply(good[:-1] + bytes([good[-1] ^ 0xFF]), 1, 3) == "checksum"
    assert diagnose_reply(b"\xaa\x55\x17" + good, 1, 3) == "garbled"
    assert diagnose_reply(bytes(range(100, 120)), 1, 3) == "garbled"


def blob_to_reply(raw: bytes) -> bytes:
    """Byte 0 picks: random bytes, a reply-shaped frame with random CRC, or a valid reply after noise."""
    if not raw:
        return raw
    mode, body = raw[0] % 3, raw[1:]
    if mode == 0:
        return body
    if mode == 1:
        return bytes([1, 3, 12]) + body[:14]
    noise, words = body[: body[0] % 4] if body else b"", [b for b in body[4:10]]
    return noise + read_reply(1, words + [0] * (6 - len(words)))


@pytest.mark.slow
@settings(max_examples=10_000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=40))
def test_rtu_decoding_never_crashes_and_never_accepts_a_bad_crc(raw):
    stream = blob_to_reply(raw)
    words = parse_read_reply(stream, 1, 6)
    assert diagnose_reply(stream, 1, 3) in ("timeout", "partial", "checksum", "garbled", "mismatch")
    if words is not None:
        frame = read_reply(1, words)  # what a correct device would have sent for these words
        assert frame in stream
        assert crc16_modbus(frame[:-2]) == frame[-2:]
        assert len(words) == 6 and all(0 <= w <= 0xFFFF for w in words)

"""Start-up check that the hands' bus traffic fits the control loop, per transport.

One hand exchange per tick writes ANGLE_SET and reads ANGLE_ACT, FORCE_ACT and ERROR..TEMP. Its wire time is the
request and reply bytes (serial and Modbus: 10 bits a byte at the baud rate, 8N1; Modbus adds the 3.5-character
silence after each frame) or CAN frame bits (+20 % for bit stuffing) at the bit rate, plus a device turnaround
per transaction (an assumption: measure it on the hardware). Hands sharing one link (both hands on one CAN
channel, or on one RS485 port) add up.

If one link's cycle does not fit `budget_share` of a period, the hands are exchanged every n-th tick instead,
with a message; if that leaves them below `min_share` of the loop rate the start is refused.

Retries (`plan_hand_timing`): a hand is stale when its latest request goes unanswered for max_age_periods x the
exchange interval, and the answer is the whole cycle. A lost reply costs a try's timeout and the operation once
more, so the timeout per try is derived from the operation's own wire time (TIMEOUT_FACTOR times the longest
operation, at least TIMEOUT_FLOOR_S for the OS and USB adapter latency the wire math does not see) and the
retries from how many lost replies the cycle can absorb before the data goes stale. A budget that cannot retry
even one lost reply in time is refused at start-up; the budget is printed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from deploy.errors import DeployError
from deploy.hands import frames, tables
from deploy.hands.can_frames import chunks, frame_bits
from deploy.hands.tables import REGISTERS

TURNAROUND_S = {"serial": 1e-3, "modbus": 1e-3, "can": 0.2e-3}  # assumed device reply latency per transaction
BITS_PER_BYTE = 10  # 8N1
MODBUS_SILENCE_CHARS = 3.5
CAN_STUFFING = 1.2
CYCLE_WRITES = ("ANGLE_SET",)


def _state_reads() -> list[tuple]:
    return [tables.contiguous(names) for names in tables.STATE_BLOCKS]


def _serial_bytes() -> list[int]:
    """Bytes on the wire per transaction (request + reply), vendor EB 90 frames."""
    reply = lambda n: n + 3 + frames.OVERHEAD  # noqa: E731
    out = [len(frames.encode_write(1, REGISTERS[w].address, b"\0" * REGISTERS[w].nbytes)) + reply(1)
           for w in CYCLE_WRITES]
    for regs in _state_reads():
        n = sum(r.nbytes for r in regs)
        out.append(len(frames.encode_read(1, regs[0].address, n)) + reply(n))
    return out


def _modbus_chars() -> list[float]:
    """Characters per transaction: write multiple (9 + 2N) + ack 8; read 8 + reply (5 + 2N); + two silences."""
    silence = 2 * MODBUS_SILENCE_CHARS
    out = [9 + 2 * REGISTERS[w].modbus_count + 8 + silence for w in CYCLE_WRITES]
    for regs in _state_reads():
        out.append(8 + 5 + 2 * sum(r.modbus_count for r in regs) + silence)
    return out


def _can_bits() -> list[float]:
    """Bits per frame pair (request + reply), one pair per chunk of at most 8 bytes."""
    out = [(frame_bits(n) + frame_bits(1)) * CAN_STUFFING
           for w in CYCLE_WRITES for _, n in chunks(REGISTERS[w], REGISTERS[w].can_address)]
    for regs in _state_reads():
        out += [(frame_bits(1) + frame_bits(n)) * CAN_STUFFING for r in regs for _, n in chunks(r, r.can_address)]
    return out


def _transaction_bits(transport: str) -> list[float]:
    if transport == "serial":
        return [b * BITS_PER_BYTE for b in _serial_bytes()]
    if transport == "modbus":
        return [c * BITS_PER_BYTE for c in _modbus_chars()]
    if transport == "can":
        return _can_bits()
    raise DeployError(f"unknown hand transport {transport!r}")


def cycle_wire_s(transport: str, line_rate: float) -> tuple[float, int]:
    """(seconds, transactions) of one hand's exchange on `transport` at `line_rate` (baud or bit/s)."""
    per = _transaction_bits(transport)
    return sum(per) / line_rate + len(per) * TURNAROUND_S[transport], len(per)


def operation_s(transport: str, line_rate: float) -> list[float]:
    """Seconds of each retried operation of a cycle: on RS485 one transaction each (write ANGLE_SET, three state
    reads); on CAN the write's frames, then all state reads at once (the bus pipelines them)."""
    per = [bits / line_rate + TURNAROUND_S[transport] for bits in _transaction_bits(transport)]
    if transport != "can":
        return per
    writes = sum(len(chunks(REGISTERS[w], REGISTERS[w].can_address)) for w in CYCLE_WRITES)
    return [sum(per[:writes]), sum(per[writes:])]


@dataclass(frozen=True)
class HandRatePlan:
    every_n_ticks: int
    wire_s: float  # one cycle of the busiest link
    message: str


def plan_hand_rate(transport: str, line_rate: float, hands_per_link: int, loop_hz: float, budget_share: float,
                   min_share: float | None) -> HandRatePlan:
    """How often the hands can be exchanged; raises DeployError when not even `min_share` of the loop rate fits."""
    one, transactions = cycle_wire_s(transport, line_rate)
    wire = one * hands_per_link
    budget = budget_share / loop_hz
    every = max(1, math.ceil(wire / budget - 1e-9))
    what = (f"{hands_per_link} hand(s) x {transactions} transactions on one {transport} link at {line_rate:g} "
            f"{'bit/s' if transport == 'can' else 'baud'} take {wire * 1e3:.1f} ms a cycle; the {loop_hz:g} Hz loop "
            f"allows {budget * 1e3:.1f} ms ({budget_share:.0%} of a period)")
    if every == 1:
        return HandRatePlan(1, wire, what)
    hand_hz = loop_hz / every
    if min_share is not None and hand_hz < min_share * loop_hz:
        raise DeployError(f"the hand bus is too slow for this loop: {what}; every {every}th tick would give "
                          f"{hand_hz:.1f} Hz, below {min_share:.0%} of the loop rate. Raise the baud rate, lower "
                          "--rate, or give each hand its own link")
    return HandRatePlan(every, wire, f"{what}: hands exchanged every {every} ticks ({hand_hz:.1f} Hz)")


TIMEOUT_FACTOR = 3.0  # a try waits this many times its operation's expected time before it counts as lost
TIMEOUT_FLOOR_S = {"serial": 0.01, "modbus": 0.01, "can": 0.005}  # OS scheduling, USB adapter latency
MAX_RETRIES = 3  # beyond these the link is reopened (HandPair's reconnect) rather than asked again


@dataclass(frozen=True)
class HandTiming:
    timeout_s: float  # per try
    retries: int  # tries after the first, per operation
    cycle_s: float  # one exchange of the busiest link, nothing lost
    retry_s: float  # what one lost reply adds: a timeout and the longest operation again
    stale_s: float  # how long a request may go unanswered before the hand is stale
    lost_replies: int  # lost replies one exchange absorbs and still answers before stale_s
    message: str


def plan_hand_timing(transport: str, line_rate: float, hands_per_link: int, loop_hz: float, every_n_ticks: int,
                     max_age_periods: float, timeout_s: float | None = None,
                     retries: int | None = None) -> HandTiming:
    """Timeout and retries for the hand buses; given values (--hand-timeout, --hand-retries) are checked instead of
    derived. Raises DeployError when not even one lost reply can be retried before the data goes stale."""
    ops = operation_s(transport, line_rate)
    cycle = sum(ops) * hands_per_link
    derived = timeout_s is None
    timeout = max(TIMEOUT_FLOOR_S[transport], TIMEOUT_FACTOR * max(ops)) if derived else timeout_s
    retry = timeout + max(ops)
    stale = max_age_periods * every_n_ticks / loop_hz
    lost = int((stale - cycle) // retry) if stale > cycle else 0
    if lost < 1:
        given = "" if derived else f"--hand-timeout {timeout_s:g}: "
        raise DeployError(f"{given}a lost hand reply ({timeout * 1e3:.1f} ms timeout + {max(ops) * 1e3:.1f} ms to ask "
                          f"again, after a {cycle * 1e3:.1f} ms cycle) cannot be retried before the hand is stale "
                          f"({stale * 1e3:.1f} ms = {max_age_periods:g} exchange periods): lower --hand-timeout, "
                          "raise --max-input-age-periods, lower --rate, or use a faster link")
    tries_after = max(1, min(lost, MAX_RETRIES)) if retries is None else retries
    message = (f"tries time out after {timeout * 1e3:.1f} ms, {tries_after} retries; {lost} lost replies fit in the "
               f"{stale * 1e3:.1f} ms before a hand is stale (a {cycle * 1e3:.1f} ms cycle, {retry * 1e3:.1f} ms a "
               "lost reply)")
    return HandTiming(timeout, tries_after, cycle, retry, stale, lost, message)

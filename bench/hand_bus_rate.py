"""Hand cycle rate on each Inspire transport, compared with the line limit for the same bytes.

    python bench/hand_bus_rate.py [--seconds 1.0] [--repeats 5] [--transports serial modbus can]

A cycle drives both hands one after the other: write ANGLE_SET, then read the state (ANGLE_ACT, FORCE_ACT,
ERROR..TEMP). Hands: left id 1, right id 2, each on its own link (two ptys for serial and Modbus, one RS485
port per hand as on the G1; two virtual CAN channels, because python-can's virtual bus would copy every frame
to the other hand's queues in user space, a cost a kernel-filtered SocketCAN bus does not have).

A pty has no baud rate, so the simulated hands pace themselves: each request + reply is booked on a virtual
wire (8N1: 10 bits per byte at --baudrate; CAN: frame bits at 1 Mbit/s, stuffing bits not counted) and the
reply is sent only when that wire would have delivered it. A host can therefore never beat the line, and
ratio = measured cycle rate / line-limited cycle rate (the bits the devices saw per cycle, at the line rate)
tells how much of the line the bus code and the OS waste. "sim lag" is how late the simulated hands themselves
sent replies after their wire deadline (their threads were not scheduled in time: a loaded machine); it is
included in the measured time, so on a busy machine the ratio understates the bus code. The last line is
`hand_bus_rate: <min ratio over transports>` (a transport's ratio is the median over repeats; goal >= 0.9).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from deploy.errors import HandLinkError  # noqa: E402
from deploy.hands import make_hand_bus  # noqa: E402
from deploy.hands.simulated import start_simulated_hand  # noqa: E402

SIDES = (("left", 1), ("right", 2))


def start_pair(transport: str, baudrate: int):
    sims, buses = [], []
    for side, hand_id in SIDES:
        options = {"baudrate": baudrate} if transport != "can" else {}
        sim = start_simulated_hand(transport, side, hand_id=hand_id, **options)
        sims.append(sim)
        buses.append(make_hand_bus(transport, side, **sim.bus_kwargs()))
    for bus in buses:
        bus.connect()
        bus.configure([1000] * 6, [1000] * 6)
    return sims, buses


def run_repeat(sims, buses, seconds: float) -> tuple[float, float, float, int]:
    """(good cycles per second, line-limited cycles per second, simulator lag per cycle, failed cycles) over
    one timed window. A cycle that ends in HandLinkError (every try timed out) still spends its time."""
    bits0 = [sim.wire_bits for sim in sims]
    late0 = sum(sim.late_s for sim in sims)
    cycles = failed = 0
    start = time.perf_counter()
    while True:
        phase = 2 * math.pi * (cycles + failed) / 50.0
        target = [int(500 + 400 * math.sin(phase + k)) for k in range(6)]
        try:
            for bus in buses:
                bus.write_angles(target)
                bus.read_state()
            cycles += 1
        except HandLinkError:
            failed += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            break
    wire_s = sum((sim.wire_bits - b0) / sim.line_rate for sim, b0 in zip(sims, bits0, strict=True))
    total = cycles + failed
    return cycles / elapsed, total / wire_s, (sum(sim.late_s for sim in sims) - late0) / total, failed


def bench_transport(transport: str, seconds: float, repeats: int, baudrate: int) -> dict:
    sims, buses = start_pair(transport, baudrate)
    try:
        for bus in buses:  # warm-up: first-call allocations, thread start-up
            for _ in range(5):
                bus.write_angles([500] * 6)
                bus.read_state()
        runs = [run_repeat(sims, buses, seconds) for _ in range(repeats)]
        line_rate = sims[0].line_rate
        failures = sum(sum(bus.stats.failures.values()) for bus in buses)
    finally:
        for bus in buses:
            bus.disconnect()
        for sim in sims:
            sim.stop()
    ratios = [rate / limit for rate, limit, _, _ in runs]
    return {
        "transport": transport,
        "rate": statistics.median(r for r, _, _, _ in runs),
        "limit": statistics.median(limit for _, limit, _, _ in runs),
        "sim_lag_ms": 1e3 * statistics.median(lag for _, _, lag, _ in runs),
        "failed_cycles": sum(f for _, _, _, f in runs),
        "ratio": statistics.median(ratios),
        "ratio_min": min(ratios),
        "ratio_max": max(ratios),
        "bits_per_cycle": line_rate / statistics.median(limit for _, limit, _, _ in runs),
        "line": f"{baudrate} baud 8N1" if transport != "can" else "1 Mbit/s CAN",
        "failures": failures,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="length of one timed repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--transports", nargs="+", default=["serial", "modbus", "can"])
    parser.add_argument("--baudrate", type=int, default=115200, help="RS485 line rate (serial and Modbus)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    logging.getLogger("pymodbus").setLevel(
        logging.CRITICAL
    )  # a timed-out try is counted in the failed-tries column

    print(
        f"hand bus cycle rate, both hands per cycle (write ANGLE_SET + read state each); {os.cpu_count()} CPUs"
    )
    print(
        f"{'transport':<9} {'line':<20} {'bytes/cycle':>11} {'line limit':>11} {'measured':>10} "
        f"{'ratio':>6} {'(min..max)':>12} {'sim lag/cycle':>13} {'failed tries':>12} {'failed cycles':>13}"
    )
    results = []
    for transport in args.transports:
        r = bench_transport(transport, args.seconds, args.repeats, args.baudrate)
        results.append(r)
        size = f"{r['bits_per_cycle'] / 10:.0f} B" if transport != "can" else f"{r['bits_per_cycle']:.0f} bit"
        print(
            f"{transport:<9} {r['line']:<20} {size:>11} {r['limit']:>8.1f} Hz {r['rate']:>7.1f} Hz "
            f"{r['ratio']:>6.3f} {r['ratio_min']:>5.3f}..{r['ratio_max']:<5.3f} {r['sim_lag_ms']:>10.3f} ms {r['failures']:>12d} {r['failed_cycles']:>13d}"
        )
    print(f"hand_bus_rate: {min(r['ratio'] for r in results):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

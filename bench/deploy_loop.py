"""Loop timing of the deploy runtime: period error p50/p99/max at 30 and 50 Hz, both hands on each mocked transport.

    python bench/deploy_loop.py [--duration 10] [--rates 30 50] [--transports serial modbus can]

Each run is a full `--dry-run` (simulated body and tracker, two simulated Inspire hands speaking the transport's
real bytes at its line rate, the dev policy). Period error = |wake-up(k) - wake-up(k-1) - dt|. The last line is
`deploy_loop_p99_ms: <worst p99 over all runs>` (goal: < 0.5 ms). `--rt-priority N` runs the loop thread
SCHED_FIFO as one would on the robot; without it the numbers include whatever else the machine is doing.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from deploy.devpolicy import build_dev_policy  # noqa: E402
from deploy.safety import SafetyConfig  # noqa: E402
from deploy.session import DeployOptions, Session  # noqa: E402


def run_once(policy: Path, transport: str, rate: float, log_dir: Path, args) -> dict:
    safety = SafetyConfig(zero_torque_s=0.2, ramp_s=0.5, auto_start_after_s=0.2, damp_s=0.3,
                          max_input_age_periods=args.max_input_age_periods)
    options = DeployOptions(policy=str(policy), dry_run=True, hand_bus=transport, rate=rate, duration=args.duration,
                            log_dir=str(log_dir), auto_start=True, safety=safety, realtime_priority=args.rt_priority,
                            hand_timeout=args.hand_timeout)
    with Session(options) as session:
        return session.run()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per run")
    parser.add_argument("--rates", type=float, nargs="+", default=[30.0, 50.0])
    parser.add_argument("--transports", nargs="+", default=["serial", "modbus", "can"])
    parser.add_argument("--rt-priority", type=int, default=None, metavar="N",
                        help="SCHED_FIFO priority for the loop thread, as on the robot (needs root/CAP_SYS_NICE)")
    parser.add_argument("--max-input-age-periods", type=float, default=2.0,
                        help="staleness limit (the runtime's default 2); raise it when a busy machine starves the "
                             "simulated hands and ends runs early")
    parser.add_argument("--hand-timeout", type=float, default=None, help="bus timeout per try (default per transport)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        policy = build_dev_policy(Path(tmp) / "dev.onnx")
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        print(f"cpu count {os.cpu_count()}, load average {load:.2f}, {args.duration:.0f} s per run, "
              f"staleness limit {args.max_input_age_periods:g} periods")
        print(f"{'transport':<9} {'rate':>5} {'ticks':>6} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8} "
              f"{'overruns':>8} {'compute p99':>11} {'faults':>6}  scheduling")
        for transport in args.transports:
            for rate in args.rates:
                s = run_once(policy, transport, rate, Path(tmp) / f"{transport}-{rate:g}", args)
                err = s["period_error_ms"]
                worst = max(worst, err["p99"])
                print(f"{transport:<9} {rate:>5.0f} {s['ticks']:>6} {err['p50']:>8.3f} {err['p99']:>8.3f} "
                      f"{err['max']:>8.3f} {s['overruns']:>8} {s['compute_ms']['p99']:>11.3f} {len(s['faults']):>6}  "
                      f"{s['scheduling']}", flush=True)
                for fault in s["faults"]:
                    print(f"    fault: {fault}")
    print(f"deploy_loop_p99_ms: {worst:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""`robot-hoi deploy` (and `python -m deploy`): run a policy on the robot, or a dry run against simulated IO.

Only argparse here; the runtime is imported inside the handler so `robot-hoi --help` stays fast.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import traceback

EPILOG = """examples:
  robot-hoi deploy --dry-run --policy policies/dev.onnx --duration 5 --auto-start
  robot-hoi deploy --dry-run --policy policies/dev.onnx --hand-bus can --auto-start
  robot-hoi deploy --dry-run --policy P.onnx --hand-bus serial --hand-port /dev/ttyUSB2 /dev/ttyUSB1   (hands bench)
  robot-hoi deploy --policy P.onnx --dds-interface eth0 --hand-port /dev/ttyUSB2 /dev/ttyUSB1 --tracker-port 9870
operator (real runs): Enter or remote L1+A held 0.5 s = confirm (stiffen from ZERO_TORQUE; start the policy from
HOLD), q or remote SELECT = stop, x or remote B = e-stop; Ctrl-C, SIGTERM, SIGHUP = DAMP, summary, exit.
exit codes: 0 completed, 1 fault, 2 usage, 3 not started, 4 refused, 5 e-stop, 70 crash, 128+N signal N
(deploy/README.md)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--policy", required=True, help="ONNX policy file following the deploy contract")
    motion = p.add_mutually_exclusive_group()
    motion.add_argument("--motion", default=None, help="reference motion .motion.npz (default: the policy's sidecar)")
    motion.add_argument("--skill", default=None, metavar="CLIP",
                        help="for a policy of several skills: the skill (a clip it learnt) to run, its sidecar "
                             "checked against the policy (default: the policy's default skill)")
    p.add_argument("--embodiment", default="g1_inspire", help="embodiment name or YAML path (default g1_inspire)")
    p.add_argument("--dry-run", action="store_true",
                   help="simulated body + tracker; simulated hands unless real hand ports are given")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="run S seconds in all, then DAMP and exit; start-up (ZERO_TORQUE 0.5 s, RAMP_TO_DEFAULT "
                        "2.0 s, HOLD until started) counts, so the policy runs about S - 3 s (default: until Ctrl-C)")
    p.add_argument("--rate", type=float, default=None, help="loop rate in Hz (default 1/control_dt; dry runs only)")
    p.add_argument("--log-dir", default=None, help="where events.jsonl, ticks/ and summary.json go")
    p.add_argument("--auto-start", action="store_true",
                   help="dry runs: confirm ZERO_TORQUE and HOLD without the operator (refused for a real body)")
    p.add_argument("--auto-start-on", default=None, metavar="IFACE",
                   help="auto-start a DDS simulator (not a dry run) reached on IFACE; must equal --dds-interface")
    p.add_argument("--status", choices=("auto", "plain", "off"), default="auto",
                   help="live status on stderr: rich line on a terminal, plain lines otherwise (default auto)")
    p.add_argument("--spin-ms", type=float, default=1.0,
                   help="busy-wait this long before each deadline for tight wake-ups (default 1.0; 0 = sleep only)")
    p.add_argument("--rt-priority", type=int, default=None, metavar="N",
                   help="run the loop thread SCHED_FIFO at priority N (1-99; needs root or CAP_SYS_NICE)")
    hands = p.add_argument_group("hands")
    hands.add_argument("--hand-bus", choices=("serial", "modbus", "can"), default="serial")
    hands.add_argument("--hand-port", nargs=2, metavar=("LEFT", "RIGHT"), default=None,
                       help="serial/modbus ports of the left and right hands")
    hands.add_argument("--hand-id", nargs=2, type=int, metavar=("LEFT", "RIGHT"), default=None,
                       help="hand ids (default 1 1 on serial/modbus, 1 2 on CAN)")
    hands.add_argument("--can-channel", default=None, help="CAN channel, e.g. can0")
    hands.add_argument("--can-interface", default=None, help="python-can interface (default socketcan)")
    hands.add_argument("--hand-timeout", type=float, default=None,
                       help="seconds per bus try (default: from the line rate, ~12 ms on RS485 at 115200 baud)")
    hands.add_argument("--hand-retries", type=int, default=None,
                       help="extra tries per bus request (default: as many lost replies as fit before the hand data "
                            "goes stale, at most 3)")
    hands.add_argument("--hand-safe-state", choices=("hold", "open"), default="hold",
                       help="on a fault: hold the last pose (default; a held box is not dropped) or open")
    hands.add_argument("--hand-force-limit", type=int, default=None,
                       help="FORCE_SET, g at the fingertip (default and maximum: the embodiment's deploy.hand_force_set)")
    hands.add_argument("--hand-speed", type=int, default=None,
                       help="SPEED_SET (default and maximum: the embodiment's deploy.hand_speed_set)")
    body = p.add_argument_group("body and tracker")
    body.add_argument("--body", choices=("sim", "dds"), default=None,
                      help="sim (dry-run default) or dds (robot default; in a dry run: a loopback DDS robot)")
    body.add_argument("--dds-interface", default=None, help="network interface to the robot, e.g. eth0")
    body.add_argument("--dds-domain", type=int, default=0)
    body.add_argument("--tracker", choices=("sim", "replay", "udp"), default=None,
                      help="pose source (dry-run default sim, robot default udp)")
    body.add_argument("--tracker-host", default="127.0.0.1", help="UDP bind address (0.0.0.0: any)")
    body.add_argument("--tracker-port", type=int, default=9870)
    safety = p.add_argument_group("safety timing")
    safety.add_argument("--zero-torque-s", type=float, default=None, help="ZERO_TORQUE duration (default 0.5)")
    safety.add_argument("--ramp-s", type=float, default=None, help="RAMP_TO_DEFAULT duration (default 2.0)")
    safety.add_argument("--damp-s", type=float, default=None, help="DAMP duration before exit (default 1.0)")
    safety.add_argument("--max-input-age-periods", type=float, default=None, metavar="N",
                        help="body/hand/tracker data older than N control periods -> DAMP (default 2)")
    safety.add_argument("--max-overruns", type=int, default=None, metavar="N",
                        help="more than N loop overruns within 1 s -> DAMP (default 5)")
    safety.add_argument("--max-stall-periods", type=float, default=None, metavar="N",
                        help="one tick ending more than N periods after its deadline -> DAMP (default 2)")
    safety.add_argument("--watchdog-s", type=float, default=None, metavar="S",
                        help="loop heartbeat silent S seconds while commanding: the watchdog (a separate process "
                             "for the DDS body) damps the robot (default 0.2; 0 = off)")
    safety.add_argument("--min-hand-rate-share", type=float, default=None, metavar="F",
                        help="hands acknowledging commands below F x the loop rate (over 1 s) -> DAMP (default 0.5)")
    safety.add_argument("--remote-estop", action="store_true",
                        help="the wireless remote is the e-stop: no start without it reporting, and silent for "
                             "--remote-timeout -> DAMP")
    safety.add_argument("--remote-timeout", dest="remote_timeout_s", type=float, default=None, metavar="S",
                        help="with --remote-estop: remote silent this long -> DAMP (default 0.5)")
    safety.add_argument("--max-motor-temp", dest="max_motor_temp_c", type=float, default=None, metavar="C",
                        help="a body motor at or above C deg C refuses the start / damps (default 90)")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "deploy",
        help="run an ONNX policy on the G1 + Inspire hands (or --dry-run against simulated IO)",
        description=__doc__.splitlines()[0],
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(p)
    p.set_defaults(func=handler)


def options_from_args(args: argparse.Namespace):
    from deploy.safety import SafetyConfig
    from deploy.session import DeployOptions

    safety = SafetyConfig()
    for name in ("zero_torque_s", "ramp_s", "damp_s", "max_input_age_periods", "max_overruns", "max_stall_periods",
                 "watchdog_s", "remote_timeout_s", "min_hand_rate_share", "max_motor_temp_c"):
        value = getattr(args, name)
        if value is not None:
            setattr(safety, name, value)
    if safety.watchdog_s is not None and safety.watchdog_s <= 0:
        safety.watchdog_s = None
    safety.remote_estop = args.remote_estop
    return DeployOptions(
        policy=args.policy, motion=args.motion, skill=args.skill, embodiment=args.embodiment, dry_run=args.dry_run,
        hand_bus=args.hand_bus, hand_ports=args.hand_port, hand_ids=args.hand_id, can_channel=args.can_channel,
        can_interface=args.can_interface, hand_timeout=args.hand_timeout, hand_retries=args.hand_retries,
        hand_safe_state=args.hand_safe_state, hand_force_limit=args.hand_force_limit, hand_speed=args.hand_speed,
        body=args.body, dds_interface=args.dds_interface, dds_domain=args.dds_domain, tracker=args.tracker,
        tracker_host=args.tracker_host, tracker_port=args.tracker_port, duration=args.duration, rate=args.rate,
        log_dir=args.log_dir, auto_start=args.auto_start, auto_start_on=args.auto_start_on,
        spin_s=max(0.0, args.spin_ms) * 1e-3, realtime_priority=args.rt_priority, safety=safety, status=args.status,
    )


def handler(args: argparse.Namespace) -> int:
    """Run; the exit code says why the run ended (deploy.outcome). Signals go through deploy.signals."""
    from deploy.session import Session, format_summary
    from deploy.signals import Interrupted, SignalRouter

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    options = options_from_args(args)
    with SignalRouter() as signals:
        try:
            with Session(options) as session:
                signals.target = session.runtime
                try:
                    summary = session.run()
                finally:
                    signals.target, signals.finished = None, True
                path = session.write_summary(summary)
        except Interrupted as exc:
            print(f"deploy: {exc}; nothing was commanded", file=sys.stderr)
            return 128 + exc.signum
        except Exception as exc:
            if getattr(exc, "user_error", False):
                raise  # one line and exit 2, printed by the entry point
            with contextlib.suppress(OSError):  # stderr may be a terminal that is gone
                traceback.print_exc()
            return 70  # deploy.outcome.Outcome.CRASHED; summary.json (if the run had started) says more
    mode = "dry run" if options.dry_run else "robot"
    try:  # after SIGHUP the terminal may be gone; summary.json is already written
        print(f"deploy ({mode}): {options.policy}")
        print(format_summary(summary))
        print(f"  {'summary':<17} {path or 'not written (see above)'}", flush=True)
    except OSError:
        pass
    return summary["exit_code"]


def main(argv: list[str] | None = None) -> int:
    """Entry point for `python -m deploy` on a robot without robot_hoi installed."""
    parser = argparse.ArgumentParser(prog="python -m deploy", description=__doc__.splitlines()[0], epilog=EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return handler(args)
    except Exception as exc:
        if getattr(exc, "user_error", False):
            print(f"deploy: error: {exc}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())

"""Assemble a runtime from command-line options: policy + motion, body, tracker, hands, logs; run it; clean up.

Dry run (`dry_run=True`): the numpy SimulatedBody (or, with body "dds", a DDS loopback robot on `lo`), the
SimulatedTracker, and two simulated Inspire hands speaking the chosen transport's real bytes. Hands-only bench:
a dry run given real hand ports (or a CAN channel) uses those instead; the runtime is the same. Real run: the DDS
body, the UDP pose receiver and real hand ports are required, and the operator confirms twice: in ZERO_TORQUE
(stiffen) and in HOLD (start the policy). --auto-start confirms both by itself, for dry runs; for a simulator
reached over DDS it must name the interface (--auto-start-on IFACE), which must be a loopback interface: a real
body never gets it. Before anything opens, the policy is checked against the embodiment YAML (its `deploy`
limits included) and the log folder must be writable.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import socket
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from deploy.atomic import atomic_write_text
from deploy.body.dds_loopback import DdsLoopbackRobot
from deploy.body.simulated import SimulatedBody
from deploy.body.unitree_dds import UnitreeDdsBody
from deploy.clock import MonotonicClock
from deploy.contract import check_against_embodiment
from deploy.embodiment import load_embodiment, resolve_embodiment_path
from deploy.errors import BodyLinkError, DeployError, HandFaultError, HandLinkError
from deploy.hand_budget import plan_hand_rate, plan_hand_timing
from deploy.hand_pair import Hands
from deploy.hands import DEFAULT_BAUDRATE, DEFAULT_CAN_BITRATE, make_hand_bus
from deploy.hands.simulated import start_simulated_hand
from deploy.loop import Runtime
from deploy.motion import load_motion, load_sidecar
from deploy.observations import ObservationBuilder
from deploy.operator import KeyboardOperator, OperatorInput
from deploy.outcome import Outcome
from deploy.policy import OnnxPolicy
from deploy.runlog import EventLog, TickRecorder
from deploy.safety import SafetyConfig
from deploy.status import make_status_view
from deploy.tracking import NoTracker, ReplayTracker, SimulatedTracker
from deploy.tracking_udp import UdpPoseReceiver
from deploy.watchdog import NullWatchdog, ProcessWatchdog, ThreadWatchdog

log = logging.getLogger("deploy.session")

HAND_TRANSPORTS = ("serial", "modbus", "can")


@dataclass
class DeployOptions:
    policy: str
    motion: str | None = None
    skill: str | None = None  # a skill of a many-skill policy: its sidecar (contract.skills)
    embodiment: str = "g1_inspire"
    dry_run: bool = False
    hand_bus: str = "serial"
    hand_ports: list[str] | None = None
    hand_ids: list[int] | None = None
    can_channel: str | None = None
    can_interface: str | None = None
    hand_timeout: float | None = None
    hand_retries: int | None = None  # None: derived from the loop period and line rate (deploy.hand_budget)
    hand_safe_state: str = "hold"
    hand_force_limit: int | None = None  # FORCE_SET; None: the embodiment's deploy.hand_force_set (no higher)
    hand_speed: int | None = None  # SPEED_SET; None: the embodiment's deploy.hand_speed_set (no higher)
    hand_threads: bool = True
    body: str | None = None  # "sim" | "dds"; default sim for dry runs, dds otherwise
    dds_interface: str | None = None
    dds_domain: int = 0
    tracker: str | None = None  # "sim" | "replay" | "udp"; default sim for dry runs, udp otherwise
    tracker_host: str = "127.0.0.1"
    tracker_port: int = 9870
    duration: float | None = None
    rate: float | None = None
    log_dir: str | None = None
    auto_start: bool = False
    auto_start_on: str | None = None  # auto-start a non-dry-run DDS body on this interface (a simulator)
    spin_s: float = 0.001  # busy-wait the last stretch before each deadline (tight wake-ups; costs CPU)
    realtime_priority: int | None = None  # SCHED_FIFO priority for the loop thread (needs CAP_SYS_NICE)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    status: str = "auto"  # live status line: "auto" (rich on a terminal, plain lines otherwise), "plain", "off"


class Session(contextlib.ExitStack):
    """Everything a run needs, opened in order and closed in reverse (hands to their safe state first)."""

    def __init__(self, options: DeployOptions):
        super().__init__()
        self.options = options
        self.clock = MonotonicClock(spin_s=options.spin_s)
        self.runtime: Runtime | None = None
        self.description: dict = {}

    def __enter__(self) -> Session:
        super().__enter__()
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        return self

    # ---------------------------------------------------------------- building blocks
    def _build(self) -> None:
        o = self.options
        if o.hand_bus not in HAND_TRANSPORTS:
            raise DeployError(f"--hand-bus must be one of {', '.join(HAND_TRANSPORTS)}, got {o.hand_bus!r}")
        auto_start = self._check_auto_start()
        real_hand_ports, hand_ids = self._check_hand_options()
        policy = OnnxPolicy(o.policy)
        contract = policy.contract
        embodiment_path = resolve_embodiment_path(o.embodiment)
        check_against_embodiment(contract, embodiment_path)
        embodiment = load_embodiment(embodiment_path)
        self.hand_settings = self._hand_settings(embodiment)
        motion = self._motion(contract)
        rate = self._rate(contract)
        self.log_dir = log_dir = self._log_dir()

        body = self._body(contract)
        tracker = self._tracker(motion, contract)
        if o.dry_run and hasattr(body, "imu_quat_source") and hasattr(tracker, "true_robot_quat_wxyz"):
            body.imu_quat_source = tracker.true_robot_quat_wxyz  # one simulated world: IMU agrees with mocap
        hands = self._hands(contract, real_hand_ports, hand_ids, rate)

        try:
            events = EventLog(self.clock, log_dir / "events.jsonl")
            self.callback(events.close)
            recorder = TickRecorder(log_dir)
            self.callback(recorder.close)
        except OSError as exc:
            raise DeployError(f"--log-dir {log_dir}: not writable ({exc.strerror or exc})") from None
        safety = o.safety
        if auto_start and safety.auto_start_after_s is None:
            safety.auto_start_after_s = 0.5
        operator = OperatorInput() if auto_start else KeyboardOperator()
        status = make_status_view(o.status)
        self.callback(status.close)
        mode_machine = embodiment.mode_machine
        watchdog = self._watchdog(body, contract, rate, mode_machine)
        self.runtime = Runtime(contract, policy, ObservationBuilder(contract, motion), body, tracker, hands,
                               clock=self.clock, safety=safety, operator=operator, events=events,
                               recorder=recorder, rate_hz=rate, realtime_priority=o.realtime_priority,
                               expected_mode_machine=mode_machine, status=status, lock_memory=not o.dry_run,
                               watchdog=watchdog)
        events.log("session", **self.description, log_dir=str(log_dir))
        events.log("hand_budget", every_n_ticks=hands.every_n_ticks, message=self.description["hand_budget"])

    def _hand_settings(self, embodiment) -> tuple[int, int]:
        """(FORCE_SET, SPEED_SET) for both hands: the embodiment's deploy values, the policy's training assumption;
        the command line may lower them, never raise them."""
        o = self.options
        out = []
        for flag, given, key in (("--hand-force-limit", o.hand_force_limit, "hand_force_set"),
                                 ("--hand-speed", o.hand_speed, "hand_speed_set")):
            assumed = getattr(embodiment.limits, key)
            if given is not None and not 0 <= given <= assumed:
                raise DeployError(f"{flag} {given} is above the embodiment's deploy.{key} {assumed} (what the policy "
                                  f"was validated with; {embodiment.path}): give 0..{assumed}")
            out.append(assumed if given is None else given)
        self.description["hand_settings"] = f"FORCE_SET {out[0]} g, SPEED_SET {out[1]}"
        return out[0], out[1]

    def _log_dir(self) -> Path:
        """The run's log folder, created and proven writable before anything is opened (a usage error if not)."""
        o = self.options
        log_dir = Path(o.log_dir) if o.log_dir else Path("runs") / "deploy" / time.strftime("%Y%m%d-%H%M%S")
        try:
            log_dir.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=log_dir):
                pass
        except OSError as exc:
            raise DeployError(f"--log-dir {log_dir}: not writable ({exc.strerror or exc})") from None
        return log_dir

    def _check_auto_start(self) -> bool:
        """--auto-start is for simulated bodies; a DDS body this process did not simulate must be a simulator on
        this machine: its interface must be a loopback interface (a robot is never reached over one)."""
        o = self.options
        if o.auto_start_on is not None:
            if o.dry_run or (o.body or "dds") != "dds" or o.dds_interface != o.auto_start_on:
                raise DeployError(f"--auto-start-on {o.auto_start_on} is for a DDS simulator on that interface: "
                                  f"give --dds-interface {o.auto_start_on} without --dry-run")
            if not is_loopback_interface(o.auto_start_on):
                raise DeployError(f"--auto-start-on {o.auto_start_on}: {o.auto_start_on} is not a loopback interface; "
                                  "automatic start is only for a simulator on this machine (on a robot's "
                                  "interface the operator confirms)")
            return True
        if o.auto_start and not o.dry_run:
            raise DeployError("--auto-start is only for dry runs and simulation: on a real body the operator "
                              "confirms (for a DDS simulator, name its interface with --auto-start-on IFACE)")
        return o.auto_start

    def _motion(self, contract):
        o = self.options
        if o.motion:
            return load_motion(o.motion)
        return load_sidecar(contract, o.skill, hint=" (or pass --motion)")

    def _rate(self, contract) -> float:
        o = self.options
        native = 1.0 / contract.control_dt
        if o.rate is None:
            return native
        if o.rate <= 0 or not math.isfinite(o.rate):
            raise DeployError(f"--rate must be a positive number, got {o.rate}")
        if not o.dry_run and not math.isclose(o.rate, native, rel_tol=1e-3):
            raise DeployError(f"--rate {o.rate} Hz differs from the policy's {native:.3f} Hz; only a dry run may do that")
        return o.rate

    def _body(self, contract):
        o = self.options
        kind = o.body or ("sim" if o.dry_run else "dds")
        self.description["body"] = kind
        if kind == "sim":
            if not o.dry_run:
                raise DeployError("the simulated body is only for --dry-run")
            body = SimulatedBody(contract.num_body, clock=self.clock)
        elif kind == "dds":
            interface = o.dds_interface
            if o.dry_run:
                interface = interface or "lo"
                robot = DdsLoopbackRobot(o.dds_domain, interface, contract.num_body).start()
                self.callback(robot.stop)
                self.description["body"] = f"dds loopback robot on {interface}, domain {o.dds_domain}"
            body = UnitreeDdsBody(contract.num_body, domain_id=o.dds_domain, interface=interface, clock=self.clock)
        else:
            raise DeployError(f"--body must be 'sim' or 'dds', got {kind!r}")
        try:
            body.connect()
        except BodyLinkError as exc:
            raise DeployError(f"the body did not come up: {exc}") from exc
        self.callback(body.close)
        return body

    def _watchdog(self, body, contract, rate: float, mode_machine: int | None):
        """Damps when the loop's heartbeat stops: a child process with its own DDS participant for a DDS body (it
        outlives a killed runtime), a thread for the in-process simulated body."""
        o = self.options
        if o.safety.watchdog_s is None:
            watchdog = NullWatchdog()
        elif isinstance(body, UnitreeDdsBody):
            watchdog = ProcessWatchdog(timeout_s=o.safety.watchdog_s, damp_s=o.safety.damp_s, period_s=1.0 / rate,
                                       damp_kd=o.safety.damp_kd, num_joints=contract.num_body,
                                       domain_id=o.dds_domain, interface=body.interface, mode_machine=mode_machine)
        else:
            watchdog = ThreadWatchdog(o.safety.watchdog_s)
        self.callback(watchdog.close)
        self.description["watchdog"] = watchdog.description
        return watchdog

    def _tracker(self, motion, contract):
        o = self.options
        if not contract.needs_tracker:  # its observation reads no tracked pose: no mocap to ask for
            self.description["tracker"] = "none (the policy reads no tracked pose)"
            if o.tracker is not None:
                log.warning("--tracker %s unused: %s reads no tracked pose", o.tracker, contract.source)
            return NoTracker()
        kind = o.tracker or ("sim" if o.dry_run else "udp")
        self.description["tracker"] = kind
        if kind == "sim":
            tracker = SimulatedTracker(motion, clock=self.clock)
        elif kind == "replay":
            if motion is None:
                raise DeployError("--tracker replay needs a motion (--motion or the policy's sidecar)")
            tracker = ReplayTracker(motion, clock=self.clock)
        elif kind == "udp":
            tracker = UdpPoseReceiver(o.tracker_host, o.tracker_port, clock=self.clock)
            self.description["tracker"] = f"udp {o.tracker_host}:{o.tracker_port}"
        else:
            raise DeployError(f"--tracker must be sim, replay or udp, got {kind!r}")
        tracker.connect()
        self.callback(tracker.close)
        return tracker

    def _check_hand_options(self) -> tuple[bool, list[int]]:
        """(real ports?, hand ids): checked before anything opens, so a wrong command line touches no hardware."""
        o = self.options
        transport = o.hand_bus
        real_ports = bool(o.hand_ports) or bool(o.can_channel)
        if not o.dry_run and not real_ports:
            raise DeployError("a real run needs the hands: --hand-port LEFT RIGHT (serial/modbus) or --can-channel")
        if o.hand_ports and len(o.hand_ports) != 2:
            raise DeployError(f"--hand-port takes two ports (left, right), got {len(o.hand_ports)}")
        if transport == "can" and o.hand_ports:
            raise DeployError("--hand-bus can uses --can-channel, not --hand-port")
        if transport != "can" and o.can_channel:
            raise DeployError(f"--can-channel needs --hand-bus can (got {transport})")
        hand_ids = o.hand_ids or ([1, 2] if transport == "can" else [1, 1])
        if len(hand_ids) != 2:
            raise DeployError(f"--hand-id takes two ids (left, right), got {hand_ids}")
        return real_ports, hand_ids

    def _hands(self, contract, real_ports: bool, hand_ids: list[int], rate: float) -> Hands:
        o = self.options
        transport = o.hand_bus
        sim_options = {"channel": f"inspire-sim-{id(self):x}"} if transport == "can" else {}  # one CAN bus
        links = []
        for i, side in enumerate(("left", "right")):
            if real_ports:
                if transport == "can":
                    kwargs = {"can_channel": o.can_channel, "can_interface": o.can_interface or "socketcan"}
                else:
                    kwargs = {"port": o.hand_ports[i]}
                kwargs["hand_id"] = hand_ids[i]
            else:
                sim = start_simulated_hand(transport, side, hand_id=hand_ids[i], **sim_options)
                self.callback(sim.stop)
                kwargs = sim.bus_kwargs()
            links.append(kwargs)
        self.description["hands"] = f"{transport} ({'real ports' if real_ports else 'simulated devices'})"
        line_rate, per_link = _line_rate(transport, links[0]), _hands_per_link(links)
        plan = plan_hand_rate(transport, line_rate, per_link, rate, o.safety.hand_bus_budget_share,
                              o.safety.min_hand_rate_share)
        timing = plan_hand_timing(transport, line_rate, per_link, rate, plan.every_n_ticks,
                                  o.safety.max_input_age_periods, o.hand_timeout, o.hand_retries)
        self.description["hand_budget"] = plan.message
        self.description["hand_timing"] = timing.message
        buses = [make_hand_bus(transport, side, **kwargs, timeout=timing.timeout_s, retries=timing.retries,
                               safe_pose=o.hand_safe_state) for side, kwargs in zip(("left", "right"), links, strict=True)]
        hands = Hands(buses[0], buses[1], contract.hands, clock=self.clock,
                      force_limits=[self.hand_settings[0]] * 6, speeds=[self.hand_settings[1]] * 6,
                      safe_state=o.hand_safe_state, threaded=o.hand_threads, every_n_ticks=plan.every_n_ticks)
        self.callback(hands.close)  # registered before connect: a half-connected pair is still closed
        try:
            hands.connect()
        except (HandLinkError, HandFaultError) as exc:  # cable, power, port, id: the operator can fix these
            raise DeployError(f"the hands did not come up: {exc}") from exc
        with contextlib.suppress(OSError):  # the operator sees what the hands' bus can do before anything moves
            print(f"deploy: hand bus: {plan.message}; {timing.message}", file=sys.stderr, flush=True)
        return hands

    # ---------------------------------------------------------------- running
    def run(self) -> dict:
        """Run; a crash still leaves a summary.json (outcome CRASHED) before the exception goes on."""
        try:
            summary = self.runtime.run(self.options.duration)
        except Exception:
            summary = self._with_setup(self.runtime.summary())
            summary.update(outcome=Outcome.CRASHED.name, exit_code=Outcome.CRASHED.code)
            self.write_summary(summary)
            raise
        return self._with_setup(summary)

    def _with_setup(self, summary: dict) -> dict:
        summary.update({"policy": str(self.options.policy), "dry_run": self.options.dry_run,
                        "log_dir": str(self.log_dir), "setup": dict(self.description)})
        return summary

    def write_summary(self, summary: dict) -> Path | None:
        """summary.json, fsynced; None (and one line on stderr) when the disk refuses it: the run is over, so a
        failed write must not turn its exit code into a crash."""
        path = self.log_dir / "summary.json"
        try:
            atomic_write_text(path, json.dumps(summary, indent=2, default=str) + "\n", fsync=True)
        except OSError as exc:
            with contextlib.suppress(OSError):
                print(f"deploy: {path}: summary.json not written ({exc})", file=sys.stderr, flush=True)
            return None
        return path


IFF_LOOPBACK = 0x8  # linux/if.h


def is_loopback_interface(name: str) -> bool:
    """Whether `name` is one of this machine's loopback interfaces (Linux: its IFF_LOOPBACK flag; elsewhere lo/lo0)."""
    if name not in {n for _, n in socket.if_nameindex()}:
        return False
    try:
        return bool(int((Path("/sys/class/net") / name / "flags").read_text(), 16) & IFF_LOOPBACK)
    except (OSError, ValueError):
        return name in ("lo", "lo0")


def _line_rate(transport: str, bus_kwargs: dict) -> float:
    """Baud (RS485) or bit rate (CAN) a bus built from these make_hand_bus arguments runs at."""
    if transport == "can":
        return float(bus_kwargs.get("can_bitrate", DEFAULT_CAN_BITRATE))
    return float(bus_kwargs.get("baudrate", DEFAULT_BAUDRATE))


def _hands_per_link(bus_kwargs: list[dict]) -> int:
    """Hands on the busiest link: both on one CAN channel or one RS485 port add up."""
    links = [kw.get("can_channel") or kw.get("port") or i for i, kw in enumerate(bus_kwargs)]
    return max(links.count(link) for link in links)


def format_summary(summary: dict) -> str:
    def ms(d: dict) -> str:
        if d.get("p50") is None:
            return "n/a"
        return f"p50 {d['p50']:.3f} ms  p99 {d['p99']:.3f} ms  max {d['max']:.3f} ms"

    phases = ", ".join(f"{k} {v:.2f} s" for k, v in summary["phase_time_s"].items())
    hand_lines = []
    for side, st in summary["hands"].items():
        rate = st.get("command_rate_hz")
        hand_lines.append(
            f"{side}: {'n/a' if rate is None else f'{rate:.1f} Hz'} commanded, {st['cycles']} cycles, "
            f"{st.get('bus_retries', 0)} bus retries, {st['link_errors']} link errors, {st['reconnects']} reconnects, "
            f"{st['fault_errors']} device faults, {st['reading_faults']} bad readings, {st['late_cycles']} late"
        )
    rows = [
        ("exit", f"{summary['exit_reason'] or '-'}  [{summary['outcome']}, code {summary['exit_code']}]"),
        ("final phase", summary["final_phase"]),
        ("rate", f"{summary['rate_hz']:.1f} Hz"),
        ("ticks", f"{summary['ticks']} (policy {summary['policy_steps']}), overruns {summary['overruns']}, "
                  f"missed deadlines {summary['missed_deadlines']}"),
        ("period error", ms(summary["period_error_ms"])),
        ("wake-up lateness", ms(summary["lateness_ms"])),
        ("compute", ms(summary["compute_ms"])),
        ("phases", phases),
        ("targets", f"{summary['clamped_ticks']} ticks clamped to limits, {summary['rate_limited_ticks']} rate limited"),
        ("hands", "\n" + "\n".join(" " * 20 + line for line in hand_lines)),
        ("faults", "; ".join(summary["faults"]) or "none"),
        ("setup", ", ".join(f"{k}: {v}" for k, v in summary.get("setup", {}).items())),
        ("log", summary.get("log_dir", "-")),
    ]
    return "\n".join(f"  {name:<17} {value}" for name, value in rows)

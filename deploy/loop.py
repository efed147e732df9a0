"""The control loop: one tick = read inputs, step the safety state machine, compute and send commands.

Timing uses absolute deadlines on an injectable clock: deadline_k = start + k * dt, the loop sleeps until the
next deadline (never `sleep(dt)` after compute), counts overruns and skips deadlines it has already missed. Each
tick's lateness (wake-up - deadline), period (wake-up - previous wake-up) and compute time are recorded.

A tick, in order:
    1. collect last tick's hand exchange (hands.finish_cycle), read the body state and the tracker poses,
       poll the operator
    2. safety: input faults -> DAMP; phase transitions (see deploy.safety)
    3. phase command: zero torque / ramp / hold / policy targets / damping; targets are clamped to the joint
       limits and rate limited, then checked once more
    4. send the body command, start the hand exchange (targets, or the safe state), record the tick
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import threading
from dataclasses import dataclass

import numpy as np

from deploy.body.base import Body, BodyState
from deploy.clock import Clock, MonotonicClock
from deploy.contract import PolicyContract
from deploy.errors import BodyLinkError
from deploy.hand_pair import Hands, HandsReading
from deploy.observations import ObservationBuilder, RobotState
from deploy.operator import OperatorInput
from deploy.runlog import EventLog, TickRecorder
from deploy.safety import (
    COMMANDING_PHASES,
    Phase,
    SafetyConfig,
    TargetShaper,
    action_fault,
    command_within_limits,
    input_faults,
    tracker_faults,
)
from deploy.tracking import PoseTracker, TrackedPoses


@dataclass
class BodyCommand:
    q: np.ndarray
    dq: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    tau: np.ndarray


class Runtime:
    def __init__(
        self,
        contract: PolicyContract,
        policy,
        builder: ObservationBuilder,
        body: Body,
        tracker: PoseTracker,
        hands: Hands,
        *,
        clock: Clock | None = None,
        safety: SafetyConfig | None = None,
        operator: OperatorInput | None = None,
        events: EventLog | None = None,
        recorder: TickRecorder | None = None,
        rate_hz: float | None = None,
        gil_switch_interval_s: float | None = 2e-4,
        realtime_priority: int | None = None,
    ):
        self.contract = contract
        self.policy = policy
        self.builder = builder
        self.body = body
        self.tracker = tracker
        self.hands = hands
        self.clock = clock or MonotonicClock()
        self.safety = safety or SafetyConfig()
        self.operator = operator or OperatorInput()
        self.events = events or EventLog(self.clock)
        self.recorder = recorder or TickRecorder(None)
        self.dt = 1.0 / rate_hz if rate_hz else contract.control_dt
        # The hand I/O threads and simulated devices share the GIL with the loop; Python's default 5 ms switch
        # interval would let them delay a wake-up by milliseconds. run() shortens it while it runs.
        self.gil_switch_interval_s = gil_switch_interval_s
        # SCHED_FIFO priority for the loop thread only (Linux; needs CAP_SYS_NICE). None: normal scheduling.
        self.realtime_priority = realtime_priority
        self.num_body = contract.num_body
        self.needs_tracker = contract.uses_reference or contract.uses_object
        self.shaper = TargetShaper(contract, self.dt, self.safety.max_target_rate)

        self.phase = Phase.WAIT_STATE
        self.phase_since = self.clock.now()
        self.phase_time: dict[str, float] = {}
        self.last_action = np.zeros(contract.num_actions)
        self.policy_tick = 0
        self._policy_deadline0 = 0.0
        self._ramp_from: np.ndarray | None = None
        self._start_requested = False
        self._start_refusal: str | None = None
        self._estop_reason: str | None = None
        self._abort = threading.Event()
        self._stop_reason: str | None = None
        self.exit_reason = ""
        self.fault_reasons: list[str] = []
        self.body_send_errors = 0
        self._send_fault: str | None = None
        self.policy_steps = 0
        self.ticks = 0
        self.overruns = 0
        self.missed_deadlines = 0
        self.timing = {"lateness": [], "period": [], "compute": []}
        self._last_measured_q = np.zeros(self.num_body)
        self._clamp_state = (frozenset(), frozenset())

    # ------------------------------------------------------------------ operator hooks (thread / signal safe)
    def request_start(self) -> None:
        """Start the policy if the runtime is in HOLD (ignored in other phases)."""
        self._start_requested = self.phase == Phase.HOLD

    def request_estop(self, reason: str = "e-stop") -> None:
        """DAMP at the next tick, then exit; a second request aborts right after one damping command."""
        if self._estop_reason is not None:
            self._abort.set()
        self._estop_reason = reason

    # ------------------------------------------------------------------ state machine
    def _enter(self, phase: Phase, reason: str, now: float) -> None:
        previous = self.phase
        self.phase_time[previous.name] = self.phase_time.get(previous.name, 0.0) + (now - self.phase_since)
        self.phase = phase
        self.phase_since = now
        self.events.log("phase", tick=self.ticks, **{"from": previous.name, "to": phase.name}, reason=reason)
        if phase == Phase.DAMP:
            self.hands.request_safe_state()

    def _fault(self, reasons: list[str], now: float) -> None:
        for reason in reasons:
            self.fault_reasons.append(reason)
            self.events.log("fault", tick=self.ticks, phase=self.phase.name, reason=reason)
        self._enter(Phase.DAMP, "; ".join(reasons), now)

    def _handle_operator(self, now: float) -> None:
        for event in self.operator.poll():
            self.events.log("operator", tick=self.ticks, phase=self.phase.name, request=event)
            if event == "start":
                if self.phase == Phase.HOLD:
                    self._start_requested = True
                else:  # a start pressed during the ramp must not fire later by surprise
                    self.events.log("start_ignored", tick=self.ticks, phase=self.phase.name,
                                    reason="the policy starts only from HOLD")
            elif event == "stop":
                self._stop_reason = "operator stop"
            elif event == "estop":
                self.request_estop("operator e-stop")

    def _measured_q(self, body: BodyState | None, hands: HandsReading) -> np.ndarray:
        q_body = body.q if body is not None and body.is_finite() else self._last_measured_q
        return np.concatenate([q_body, self.hands.rad_from_units(hands.angles)])

    # ------------------------------------------------------------------ one tick
    def tick(self, deadline: float | None = None) -> bool:
        """Run one control step; returns False when the runtime should stop."""
        now = self.clock.now()
        deadline = now if deadline is None else deadline
        reading = self.hands.finish_cycle(self.safety.hand_wait_fraction * self.dt)
        body = self.body.read_state()
        poses = self.tracker.read()
        self._handle_operator(now)
        if body is not None and body.is_finite():
            self._last_measured_q = body.q.copy()

        if self.phase == Phase.WAIT_STATE:
            faults = input_faults(now, self.dt, self.safety, self.contract, body, reading, poses,
                                  need_tracker=self.needs_tracker)
            if self._estop_reason or self._stop_reason:
                self.exit_reason = f"{self._estop_reason or self._stop_reason} before start (nothing commanded)"
                return self._finish_tick(now, deadline, body, reading, poses, None, None, None)
            if not faults:
                self._enter(Phase.ZERO_TORQUE, "body, hands and tracker report fresh data", now)
            elif now - self.phase_since > self.safety.wait_timeout_s:
                self.exit_reason = f"no usable inputs within {self.safety.wait_timeout_s} s: {'; '.join(faults)}"
                self.events.log("error", tick=self.ticks, reason=self.exit_reason)
                return self._finish_tick(now, deadline, body, reading, poses, None, None, None)
        elif self.phase in COMMANDING_PHASES:
            faults = input_faults(now, self.dt, self.safety, self.contract, body, reading, poses,
                                  need_tracker=self.phase == Phase.POLICY and self.needs_tracker)
            if self._send_fault:
                faults.append(self._send_fault)
                self._send_fault = None
            if faults:
                self._fault(faults, now)
            elif self._estop_reason or self._stop_reason:
                self._enter(Phase.DAMP, self._estop_reason or self._stop_reason, now)

        target, action = None, None
        if self.phase == Phase.ZERO_TORQUE and now - self.phase_since >= self.safety.zero_torque_s:
            # start from the measured pose, inside the limits (unit conversion can land a hair outside them)
            self._ramp_from = np.clip(self._measured_q(body, reading), self.contract.joint_lower,
                                      self.contract.joint_upper)
            self.shaper.reset(self._ramp_from)
            self._enter(Phase.RAMP_TO_DEFAULT, f"ramp to default pose over {self.safety.ramp_s} s", now)
        if self.phase == Phase.RAMP_TO_DEFAULT:
            alpha = min(1.0, (now - self.phase_since) / self.safety.ramp_s) if self.safety.ramp_s > 0 else 1.0
            target = self._ramp_from + alpha * (self.contract.default_pose - self._ramp_from)
            if alpha >= 1.0:
                self._enter(Phase.HOLD, "default pose reached", now)
        elif self.phase == Phase.HOLD:
            target = self.contract.default_pose.copy()
            if self._can_start(now, poses):
                self._enter(Phase.POLICY, "operator start" if self._start_requested else "auto start", now)
                self._policy_deadline0 = deadline
                self.last_action = np.zeros(self.contract.num_actions)
        if self.phase == Phase.POLICY:
            self.policy_tick = int(round((deadline - self._policy_deadline0) / self.dt))
            target, action = self._policy_target(now, body, reading, poses)

        if self.phase == Phase.DAMP and now - self.phase_since >= self.safety.damp_s:
            self._send_damping(body)
            self.hands.begin_cycle(None)
            cause = f"fault: {self.fault_reasons[0]}" if self.fault_reasons else (self._estop_reason or self._stop_reason)
            self.exit_reason = self.exit_reason or f"{cause or 'stopped'}; damped {self.safety.damp_s} s"
            return self._finish_tick(now, deadline, body, reading, poses, action, None, None)
        command, hand_units = self._command(now, body, target)
        return self._finish_tick(now, deadline, body, reading, poses, action, command, hand_units,
                                 keep_going=not self._abort.is_set())

    def _can_start(self, now: float, poses: TrackedPoses) -> bool:
        held = now - self.phase_since
        auto = self.safety.auto_start_after_s
        if not (self._start_requested or (auto is not None and held >= auto)):
            return False
        if auto is not None and held < auto:
            return False
        problems = tracker_faults(now, self.safety.max_input_age_periods * self.dt, self.contract, poses) \
            if self.needs_tracker else []
        if problems:
            reason = "; ".join(problems)
            if reason != self._start_refusal:
                self.events.log("start_refused", tick=self.ticks, reason=reason)
                self._start_refusal = reason
            return False
        return True

    def _policy_target(self, now, body, reading, poses) -> tuple[np.ndarray | None, np.ndarray | None]:
        state = RobotState(
            joint_pos=body.q,
            joint_vel=body.dq,
            imu_quat_wxyz=body.imu_quat_wxyz,
            gyro=body.gyro,
            hand_angles=reading.angles,
            hand_forces=reading.forces,
            pelvis_pos=poses.robot.pos,
            pelvis_quat_wxyz=poses.robot.quat_wxyz,
            object_pos=poses.object.pos,
            object_quat_wxyz=poses.object.quat_wxyz,
            last_action=self.last_action,
            tick=self.policy_tick,
        )
        obs = self.builder.build(state)
        if not np.all(np.isfinite(obs)):
            bad = self._first_bad_term(state)
            self._fault([f"observation not finite ({bad})"], now)
            return None, None
        action = np.asarray(self.policy(obs), dtype=np.float64)
        problem = action_fault(action, self.contract, self.safety)
        if problem:
            self._fault([problem], now)
            return None, action
        self.last_action = action
        self.policy_steps += 1
        self.tracker.update_reference(self.policy_tick + 1)
        return self.contract.action_to_target(action, self._reference_offset(self.policy_tick + 1)), action

    def _reference_offset(self, tick: int) -> np.ndarray | None:
        """The reference joints of frame f(tick) when the policy outputs corrections to the reference."""
        if self.contract.action_offset_mode != "reference":
            return None
        motion = self.builder.ctx.motion
        return motion.joint_pos[self.contract.reference_frame(tick, motion.num_frames)]

    def _first_bad_term(self, state: RobotState) -> str:
        for name, value in self.builder.terms(state).items():
            if not np.all(np.isfinite(value)):
                return name
        return "?"

    # ------------------------------------------------------------------ commands
    def _command(self, now: float, body: BodyState | None, target: np.ndarray | None):
        n = self.num_body
        zeros = np.zeros(n)
        hand_units = None
        if self.phase in (Phase.RAMP_TO_DEFAULT, Phase.HOLD, Phase.POLICY) and target is not None:
            shaped = self.shaper(target)
            self._log_shaping()
            command = BodyCommand(shaped[:n], zeros, self.contract.kp[:n], self.contract.kd[:n], zeros)
            if not command_within_limits(command.q, command.kp, command.kd, command.tau, self.contract):
                self._fault(["command outside limits after shaping"], now)
                return self._send_damping(body), None
            hand_units = self.hands.units_from_rad(shaped[n:])
            self._send(command)
            self.hands.begin_cycle(hand_units)
            return command, hand_units
        if self.phase == Phase.ZERO_TORQUE:
            q = np.clip(self._last_measured_q, self.contract.joint_lower[:n], self.contract.joint_upper[:n])
            command = BodyCommand(q, zeros, zeros, zeros, zeros)
            self._send(command)
            self.hands.begin_cycle(None)
            return command, None
        if self.phase == Phase.DAMP:
            command = self._send_damping(body)
            self.hands.begin_cycle(None)
            return command, None
        self.hands.begin_cycle(None)  # WAIT_STATE: keep reading the hands, command nothing
        return None, None

    def _send_damping(self, body: BodyState | None) -> BodyCommand:
        n = self.num_body
        q = np.clip(self._last_measured_q, self.contract.joint_lower[:n], self.contract.joint_upper[:n])
        command = BodyCommand(q, np.zeros(n), np.zeros(n), np.full(n, self.safety.damp_kd), np.zeros(n))
        self._send(command)
        return command

    def _send(self, command: BodyCommand) -> None:
        try:
            self.body.send(command.q, command.dq, command.kp, command.kd, command.tau)
        except BodyLinkError as exc:
            self.body_send_errors += 1
            self.events.log("error", tick=self.ticks, reason=f"body send failed: {exc}")
            self._send_fault = f"body send failed: {exc}"  # acted on (DAMP) at the next tick

    def _log_shaping(self) -> None:
        names = self.contract.actuator_names
        clamped = frozenset(names[i] for i in np.flatnonzero(self.shaper.last_clamped))
        limited = frozenset(names[i] for i in np.flatnonzero(self.shaper.last_rate_limited))
        if (clamped, limited) != self._clamp_state:
            self.events.log("shaping", tick=self.ticks, phase=self.phase.name,
                            clamped_to_limits=sorted(clamped), rate_limited=sorted(limited))
            self._clamp_state = (clamped, limited)

    # ------------------------------------------------------------------ recording
    def _finish_tick(self, now, deadline, body, reading, poses, action, command, hand_units, keep_going=False):
        n, a = self.num_body, self.contract.num_actions
        nan = np.full(n, np.nan)
        self.recorder.record({
            "t": now,
            "deadline": deadline,
            "phase": int(self.phase),
            "policy_tick": self.policy_tick if self.phase == Phase.POLICY else -1,
            "q": body.q if body is not None else nan,
            "dq": body.dq if body is not None else nan,
            "imu_quat_wxyz": body.imu_quat_wxyz if body is not None else np.full(4, np.nan),
            "gyro": body.gyro if body is not None else np.full(3, np.nan),
            "body_age": now - body.stamp if body is not None else np.inf,
            "hand_angles": reading.angles,
            "hand_forces": reading.forces,
            "hand_errors": reading.errors,
            "hand_age": now - reading.stamps,
            "robot_pos": poses.robot.pos,
            "robot_quat_wxyz": poses.robot.quat_wxyz,
            "object_pos": poses.object.pos,
            "object_quat_wxyz": poses.object.quat_wxyz,
            "tracker_age": np.array([now - poses.robot.stamp, now - poses.object.stamp]),
            "action": action if action is not None else np.full(a, np.nan),
            "cmd_q": command.q if command is not None else nan,
            "cmd_kp": command.kp if command is not None else nan,
            "cmd_kd": command.kd if command is not None else nan,
            "cmd_hand_units": hand_units if hand_units is not None else np.full(12, -1),
        })
        self.ticks += 1
        return keep_going

    # ------------------------------------------------------------------ the loop
    def run(self, duration_s: float | None = None) -> dict:
        """Tick on absolute deadlines until the state machine stops (or duration_s ends the run through DAMP)."""
        clock = self.clock
        start = clock.now()
        self.phase_since = start
        deadline = start
        previous_wake = None
        previous_interval = sys.getswitchinterval()
        if self.gil_switch_interval_s is not None:
            sys.setswitchinterval(self.gil_switch_interval_s)
        self.events.log("start", rate_hz=1.0 / self.dt, policy=self.contract.source, duration_s=duration_s,
                        scheduling=self._set_realtime())
        try:
            while True:
                wake = clock.now()
                if duration_s is not None and wake - start >= duration_s and self._stop_reason is None:
                    self._stop_reason = "duration reached"
                    if self.phase == Phase.WAIT_STATE:
                        self.exit_reason = "duration reached before inputs were ready"
                keep_going = self.tick(deadline)
                done = clock.now()
                self.timing["lateness"].append(wake - deadline)
                self.timing["compute"].append(done - wake)
                if previous_wake is not None:
                    self.timing["period"].append(wake - previous_wake)
                previous_wake = wake
                if not keep_going or (self.exit_reason and self.phase == Phase.WAIT_STATE):
                    break
                deadline += self.dt
                if done > deadline:
                    skipped = math.ceil((done - deadline) / self.dt)
                    self.overruns += 1
                    self.missed_deadlines += skipped
                    if self.overruns <= 10 or self.overruns % 100 == 0:
                        self.events.log("overrun", tick=self.ticks, late_ms=(done - deadline) * 1e3,
                                        skipped=skipped, count=self.overruns)
                    deadline += skipped * self.dt
                clock.sleep_until(deadline)
        except BaseException as exc:
            self.events.log("error", tick=self.ticks, reason=f"runtime crashed: {type(exc).__name__}: {exc}")
            try:
                self._send_damping(None)
            finally:
                self.exit_reason = self.exit_reason or f"crashed: {type(exc).__name__}"
            raise
        finally:
            sys.setswitchinterval(previous_interval)
            self._restore_scheduling()
            end = clock.now()
            self.phase_time[self.phase.name] = self.phase_time.get(self.phase.name, 0.0) + (end - self.phase_since)
            self.phase_since = end
            self.events.log("stop", reason=self.exit_reason or self._stop_reason or "", ticks=self.ticks,
                            final_phase=self.phase.name)
        return self.summary()

    def _set_realtime(self) -> str:
        """Give the loop thread SCHED_FIFO if asked; threads started before keep their own scheduling."""
        self.scheduling = "normal"
        if self.realtime_priority is None:
            return self.scheduling
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.realtime_priority))
        except (AttributeError, PermissionError, OSError) as exc:
            self.events.log("warning", reason=f"real-time priority not available ({exc}); normal scheduling")
            return "normal"
        self.scheduling = f"SCHED_FIFO {self.realtime_priority}"
        return self.scheduling

    def _restore_scheduling(self) -> None:
        if self.realtime_priority is not None:
            with contextlib.suppress(AttributeError, PermissionError, OSError):
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

    def summary(self) -> dict:
        def stats_ms(values, absolute=False, minus=0.0):
            if not values:
                return {"p50": None, "p99": None, "max": None}
            arr = np.asarray(values) - minus
            arr = np.abs(arr) if absolute else arr
            return {k: float(v) * 1e3 for k, v in
                    (("p50", np.percentile(arr, 50)), ("p99", np.percentile(arr, 99)), ("max", arr.max()))}

        return {
            "exit_reason": self.exit_reason or self._stop_reason or "",
            "final_phase": self.phase.name,
            "faults": list(self.fault_reasons),
            "rate_hz": 1.0 / self.dt,
            "scheduling": getattr(self, "scheduling", "normal"),
            "ticks": self.ticks,
            "policy_steps": self.policy_steps,
            "phase_time_s": dict(self.phase_time),
            "overruns": self.overruns,
            "missed_deadlines": self.missed_deadlines,
            "lateness_ms": stats_ms(self.timing["lateness"]),
            "period_error_ms": stats_ms(self.timing["period"], absolute=True, minus=self.dt),
            "compute_ms": stats_ms(self.timing["compute"]),
            "clamped_ticks": self.shaper.clamped_ticks,
            "rate_limited_ticks": self.shaper.rate_limited_ticks,
            "body_send_errors": self.body_send_errors,
            "hands": self.hands.stats(),
        }

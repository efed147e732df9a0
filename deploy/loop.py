"""The control loop: one tick = read inputs, step the safety state machine, compute and send commands.

`Runtime.run` ticks on absolute deadlines (deploy.loop_run: timing, real-time set-up, watchdog heartbeat, crash
path); `tick()` is one control step, driven by it or, in tests, by hand on a fake clock.

Stopping: request_stop (operator, duration), request_estop and request_signal all end in DAMP for damp_s; more
stops never shorten it, only a second signal aborts after one damping command. `outcome` (deploy.outcome) says
why the run ended.

A tick, in order:
    1. collect last tick's hand exchange (hands.finish_cycle), read the body state and the tracker poses,
       poll the operator (keyboard/script) and the wireless remote
    2. safety: input, body health and identity faults -> DAMP (before stiffening: refuse); operator gates;
       phase transitions (see deploy.safety)
    3. phase command: zero torque / ramp / hold / policy targets / damping; targets are clamped to the joint
       limits and rate limited, then checked once more
    4. send the body command, start the hand exchange (targets, or the safe state), record the tick
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from deploy.body.base import Body, BodyState
from deploy.body_health import TickWatch, identity_faults
from deploy.clock import Clock, MonotonicClock
from deploy.contract import PolicyContract
from deploy.errors import BodyLinkError
from deploy.hand_pair import Hands, HandsReading
from deploy.loop_run import run_loop
from deploy.loop_timing import LoopTiming
from deploy.observations import ObservationBuilder, RobotState
from deploy.operator import OperatorInput
from deploy.outcome import Outcome, StopRequests, classify
from deploy.remote import RemotePresses
from deploy.runlog import EventLog, TickRecorder, tick_row
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
from deploy.watchdog import NullWatchdog

GATES = (Phase.ZERO_TORQUE, Phase.HOLD)  # the phases that wait for the operator's confirmation
PROMPTS = {
    Phase.ZERO_TORQUE: "robot limp (zero torque): press Enter or hold remote L1+A to stiffen and ramp to the default pose",
    Phase.HOLD: "HOLD reached: press Enter or hold remote L1+A to start the policy",
}
HAND_COMMANDING = (Phase.RAMP_TO_DEFAULT, Phase.HOLD, Phase.POLICY)


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
        expected_mode_machine: int | None = None,
        status=None,
        lock_memory: bool = False,
        watchdog=None,
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
        self.status = status  # deploy.status view, updated once per tick (None: no live view)
        self.dt = 1.0 / rate_hz if rate_hz else contract.control_dt
        # The hand I/O threads and simulated devices share the GIL with the loop; Python's default 5 ms switch
        # interval would let them delay a wake-up by milliseconds. run() shortens it while it runs.
        self.gil_switch_interval_s = gil_switch_interval_s
        # SCHED_FIFO priority for the loop thread only (Linux; needs CAP_SYS_NICE). None: normal scheduling.
        self.realtime_priority = realtime_priority
        self.lock_memory = lock_memory  # mlockall for the run (deploy.realtime); refused: a note, the run goes on
        self.watchdog = watchdog or NullWatchdog()  # deploy.watchdog: damps when the heartbeat stops
        self.scheduling = "normal"
        self.memory = "not locked (not requested)"
        self.expected_mode_machine = expected_mode_machine
        self.num_body = contract.num_body
        self.needs_tracker = contract.needs_tracker  # terms that read a tracked pose (contract.tracked_poses)
        # the safety limit, or the tighter one the policy trained under (its commands are shaped as in training)
        trained = contract.trained_rate_limit
        self.shaper = TargetShaper(contract, self.dt, self.safety.max_target_rate if trained is None
                                   else min(trained, self.safety.max_target_rate))
        stall = self.safety.max_stall_periods
        self.timing = LoopTiming(self.dt, self.safety.max_overruns, self.safety.overrun_window_s,
                                 None if stall is None else stall * self.dt)
        self.tick_watch = TickWatch(self.safety.max_input_age_periods * self.dt)
        self.remote = RemotePresses()

        self.phase = Phase.WAIT_STATE
        self.phase_since = self.clock.now()
        self.phase_time: dict[str, float] = {}
        self.last_action = np.zeros(contract.num_actions)
        self.policy_tick = 0  # policy steps taken: the reference clock, one frame a step (never skips after a stall)
        self._next_policy_tick = 0
        self._ramp_from: np.ndarray | None = None
        self._confirmed = False  # the operator confirmed the gate the runtime is waiting at
        self.start_refusal: str | None = None  # why the last start in HOLD was refused (on the status line)
        self.stops = StopRequests()
        self.exit_reason = ""
        self.fault_reasons: list[str] = []
        self.refused = False
        self.body_send_errors = 0
        self._deferred_faults: list[str] = []  # found outside a tick (failed send, overruns): acted on next tick
        self._hands_commanded_since: float | None = None
        self.policy_steps = 0
        self.ticks = 0
        self._last_measured_q = np.zeros(self.num_body)
        self._clamp_state = (frozenset(), frozenset())
        self._sync_logs = False
        self._realtime = None  # deploy.realtime.RealtimeRun while run() runs
        self.status_errors = 0  # status lines that could not be written (terminal gone): dropped

    # ------------------------------------------------------------------ stop and start hooks (thread / signal safe)
    def request_start(self) -> None:
        """Confirm the gate the runtime waits at (ZERO_TORQUE: stiffen; HOLD: start the policy)."""
        self._confirmed = self.phase in GATES

    def request_stop(self, reason: str, kind: str = "operator") -> None:
        """End the run through DAMP (kind: operator, duration, estop or signal); a second one changes nothing."""
        self.stops.request(reason, kind)

    def request_estop(self, reason: str = "e-stop") -> None:
        """DAMP at the next tick, then exit after --damp-s (a second one never shortens it)."""
        self.stops.request(reason, "estop")

    def request_signal(self, signum: int) -> None:
        self.stops.signal(signum)

    @property
    def prompt(self) -> str | None:
        """What the operator is asked to do now (None: nothing)."""
        waiting = self.phase in GATES and self.safety.auto_start_after_s is None and not self._confirmed
        return PROMPTS[self.phase] if waiting else None

    @property
    def outcome(self) -> Outcome:
        return classify(refused=self.refused, faults=bool(self.fault_reasons), stops=self.stops,
                        policy_ran=self.policy_steps > 0)

    # ------------------------------------------------------------------ state machine
    def _enter(self, phase: Phase, reason: str, now: float) -> None:
        previous = self.phase
        self.phase_time[previous.name] = self.phase_time.get(previous.name, 0.0) + (now - self.phase_since)
        self.phase = phase
        self.phase_since = now
        self._confirmed = False  # a confirmation is for one gate only
        self.start_refusal = None
        self._sync_logs = True  # made durable once this tick's commands are out
        self.events.log("phase", tick=self.ticks, **{"from": previous.name, "to": phase.name}, reason=reason)
        if self.prompt:
            self.events.log("prompt", tick=self.ticks, phase=phase.name, message=self.prompt)
        if phase == Phase.DAMP:
            self.hands.request_safe_state()
        if self._realtime is not None:
            self._realtime.policy_running(phase == Phase.POLICY)  # gc off from the first policy step on
        if phase == Phase.RAMP_TO_DEFAULT:
            self._hands_commanded_since = now

    def _fault(self, reasons: list[str], now: float) -> None:
        for reason in reasons:
            self.fault_reasons.append(reason)
            self.events.log("fault", tick=self.ticks, phase=self.phase.name, reason=reason)
        self._enter(Phase.DAMP, "; ".join(reasons), now)

    def _handle_operator(self, body: BodyState | None, now: float) -> None:
        remote = self.remote.update(body.remote_keys if body is not None else None, now)
        for source, event in [("operator", e) for e in self.operator.poll()] + [("remote", e) for e in remote]:
            self.events.log("operator", tick=self.ticks, phase=self.phase.name, request=event, source=source)
            if event == "start":
                if self.phase in GATES:
                    self._confirmed = True
                else:  # a press during the ramp must not fire later by surprise
                    self.events.log("start_ignored", tick=self.ticks, phase=self.phase.name,
                                    reason="the operator confirms in ZERO_TORQUE (stiffen) and HOLD (start) only")
            elif event == "stop":
                self.request_stop("operator stop" if source == "operator" else "remote stop")
            elif event == "estop":
                self.request_estop("operator e-stop" if source == "operator" else "remote e-stop")

    def _measured_q(self, body: BodyState | None, hands: HandsReading) -> np.ndarray:
        q_body = body.q if body is not None and body.is_finite() else self._last_measured_q
        return np.concatenate([q_body, hands.rad])

    def _health_faults(self, now: float, body: BodyState | None) -> tuple[list[str], list[str]]:
        """(identity and health faults, tick faults) of this body state."""
        if body is None:
            return [], []
        identity = identity_faults(body, self.contract.actuator_names, self.expected_mode_machine,
                                   self.safety.max_motor_temp_c)
        tick = self.tick_watch.fault(body, now)
        return identity, [tick] if tick else []

    def _hand_rate_fault(self, now: float) -> list[str]:
        share, window = self.safety.min_hand_rate_share, self.safety.hand_rate_window_s
        since = self._hands_commanded_since
        if share is None or self.phase not in HAND_COMMANDING or since is None or now - since < window:
            return []
        loop_hz = 1.0 / self.dt
        return [f"{side} hand commanded at {rate:.1f} Hz, below {share:.0%} of the {loop_hz:.0f} Hz loop"
                for side, rate in self.hands.command_rates(window).items() if rate < share * loop_hz][:1]

    # ------------------------------------------------------------------ one tick
    def tick(self, deadline: float | None = None) -> bool:
        """Run one control step; returns False when the runtime should stop."""
        now = self.clock.now()
        deadline = now if deadline is None else deadline
        reading = self.hands.finish_cycle(self.safety.hand_wait_fraction * self.dt)
        body = self.body.read_state()
        poses = self.tracker.read()
        self._handle_operator(body, now)
        if body is not None and body.is_finite():
            self._last_measured_q = body.q.copy()
        identity, tick_faults = self._health_faults(now, body)

        if self.phase == Phase.WAIT_STATE:
            faults = input_faults(now, self.dt, self.safety, self.contract, body, reading, poses,
                                  need_tracker=self.needs_tracker) + tick_faults
            if self.stops.first:
                self.exit_reason = f"{self.stops.reason} before start (nothing commanded)"
                return self._finish_tick(now, deadline, body, reading, poses, None, None, None)
            if identity:
                self.refused = True
                self.exit_reason = "refused to start (nothing commanded): " + "; ".join(identity)
                self.events.log("refused", tick=self.ticks, reason=self.exit_reason)
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
            faults += identity + tick_faults + self._deferred_faults + self._hand_rate_fault(now)
            faults += [fired] if (fired := self.watchdog.check()) else []
            self._deferred_faults = []
            if faults:
                self.refused = self.refused or bool(identity and self.phase == Phase.ZERO_TORQUE)
                self._fault(faults, now)
            elif self.stops.first:
                self._enter(Phase.DAMP, self.stops.reason, now)

        target, action = None, None
        if self.phase == Phase.ZERO_TORQUE and now - self.phase_since >= self.safety.zero_torque_s \
                and (self._confirmed or self.safety.auto_start_after_s is not None):
            # start from the measured pose, inside the limits (unit conversion can land a hair outside them)
            self._ramp_from = np.clip(self._measured_q(body, reading), self.contract.joint_lower,
                                      self.contract.joint_upper)
            self.shaper.reset(self._ramp_from)
            how = "operator confirmed" if self._confirmed else "auto start"
            self._enter(Phase.RAMP_TO_DEFAULT, f"{how}: ramp to default pose over {self.safety.ramp_s} s", now)
        if self.phase == Phase.RAMP_TO_DEFAULT:
            alpha = min(1.0, (now - self.phase_since) / self.safety.ramp_s) if self.safety.ramp_s > 0 else 1.0
            target = self._ramp_from + alpha * (self.contract.default_pose - self._ramp_from)
            if alpha >= 1.0:
                self._enter(Phase.HOLD, "default pose reached", now)
        elif self.phase == Phase.HOLD:
            target = self.contract.default_pose.copy()
            if self._can_start(now, poses):
                self._enter(Phase.POLICY, "operator start" if self._confirmed else "auto start", now)
                self._next_policy_tick = 0
                self.last_action = np.zeros(self.contract.num_actions)
        if self.phase == Phase.POLICY:
            self.policy_tick = self._next_policy_tick
            self._next_policy_tick += 1
            target, action = self._policy_target(now, body, reading, poses)

        if self.phase == Phase.DAMP and now - self.phase_since >= self.safety.damp_s:
            self._send_damping(body)
            self.hands.begin_cycle(None)
            cause = f"fault: {self.fault_reasons[0]}" if self.fault_reasons else self.stops.reason
            self.exit_reason = self.exit_reason or f"{cause or 'stopped'}; damped {self.safety.damp_s} s"
            return self._finish_tick(now, deadline, body, reading, poses, action, None, None)
        command, hand_units = self._command(now, body, target)
        if self.stops.aborted:
            self.exit_reason = self.exit_reason or f"{self.stops.reason} twice: aborted after one damping command"
        return self._finish_tick(now, deadline, body, reading, poses, action, command, hand_units,
                                 keep_going=not self.stops.aborted)

    def _can_start(self, now: float, poses: TrackedPoses) -> bool:
        held = now - self.phase_since
        auto = self.safety.auto_start_after_s
        if not (self._confirmed or (auto is not None and held >= auto)):
            return False
        if auto is not None and held < auto:
            return False
        problems = tracker_faults(now, self.safety.max_input_age_periods * self.dt, self.contract, poses) \
            if self.needs_tracker else []
        if problems:
            reason = "; ".join(problems)
            if self._confirmed or reason != self.start_refusal:  # every refused press; auto start: changes only
                self.events.log("start_refused", tick=self.ticks, reason=reason)
            self.start_refusal = reason
            self._confirmed = False  # refused: the operator presses again when the inputs are back
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
        return self.contract.action_to_target(action, self._reference_offset(self.policy_tick)), action

    def _reference_offset(self, tick: int) -> np.ndarray | None:
        """The reference joints tick t steps to (frame f(t + 1)) when the policy outputs corrections to the
        reference."""
        if self.contract.action_offset_mode != "reference":
            return None
        return self.contract.reference_offset(tick, self.builder.ctx.motion.joint_pos)

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
        if self.phase in HAND_COMMANDING and (fired := self.watchdog.check()):
            self._fault([fired], self.clock.now())  # it damped while this tick computed: never stiffen after it
        if self.phase in HAND_COMMANDING and target is not None:
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
            self._deferred_faults.append(f"body send failed: {exc}")  # acted on (DAMP) at the next tick

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
        """After the tick's commands are out: record it, and hand the logs to their writers (fsynced when the
        phase changed)."""
        self.recorder.record(tick_row(now, deadline, self.phase, self.policy_tick, body, reading, poses, action,
                                      command, hand_units, self.num_body, self.contract.num_actions))
        self.ticks += 1
        if self._sync_logs:
            self._sync_logs = False
            self.events.sync()
            self.recorder.sync()
        else:
            self.events.flush_due()
        return keep_going

    def _show_status(self) -> None:
        """Redraw the operator's status; a terminal that is gone (EIO after SIGHUP) costs the line, nothing else."""
        if self.status is None:
            return
        try:
            self.status.update(self)
        except Exception:
            self.status_errors += 1

    # ------------------------------------------------------------------ the loop
    def run(self, duration_s: float | None = None) -> dict:
        """Tick on absolute deadlines until the state machine stops (or duration_s ends the run through DAMP);
        returns the summary. The timing, the process set-up and the crash path are deploy.loop_run's."""
        return run_loop(self, duration_s)

    def summary(self) -> dict:
        outcome = self.outcome
        commanded_s = self.phase_time_commanding()
        hands = self.hands.stats()
        for entry in hands.values():
            entry["command_rate_hz"] = entry["commands"] / commanded_s if commanded_s > 0 else None
        return {
            "exit_reason": self.exit_reason or self.stops.reason or "",
            "outcome": outcome.name,
            "exit_code": outcome.code,
            "final_phase": self.phase.name,
            "faults": list(self.fault_reasons),
            "rate_hz": 1.0 / self.dt,
            "hand_rate_hz": 1.0 / (self.dt * self.hands.every_n_ticks),
            "scheduling": self.scheduling,
            "memory": self.memory,
            "watchdog": self.watchdog.description,
            "ticks": self.ticks,
            "policy_steps": self.policy_steps,
            "phase_time_s": dict(self.phase_time),
            **self.timing.summary(),
            "clamped_ticks": self.shaper.clamped_ticks,
            "rate_limited_ticks": self.shaper.rate_limited_ticks,
            "body_send_errors": self.body_send_errors,
            "logs": {"events": self.events.report(), "ticks": self.recorder.report(),
                     "status_errors": self.status_errors},
            "hands": hands,
        }

    def phase_time_commanding(self) -> float:
        """Seconds the hands were given targets (RAMP_TO_DEFAULT, HOLD, POLICY)."""
        return sum(self.phase_time.get(p.name, 0.0) for p in HAND_COMMANDING)

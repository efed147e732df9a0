"""What stands between the policy and the hardware: phases, input freshness, action sanity, target shaping.

Phases (an explicit state machine, driven by deploy.loop.Runtime):

    WAIT_STATE -> ZERO_TORQUE -> RAMP_TO_DEFAULT -> HOLD -> POLICY -> DAMP
    WAIT_STATE       nothing is sent until body, hands (and the tracker, if the policy needs it) report fresh data;
                     a robot of the wrong type (mode_machine) or already unhealthy is refused here
    ZERO_TORQUE      kp = kd = 0 (the robot hangs limp in its gantry) for at least `zero_torque_s`, and until the
                     operator confirms (keyboard Enter, remote L1+A held; --auto-start in simulation)
    RAMP_TO_DEFAULT  linear interpolation from the measured pose to default_pose over `ramp_s`, policy gains
    HOLD             default_pose until the operator starts the policy (same keys, or --auto-start)
    POLICY           joint targets from the policy
    DAMP             kp = 0, kd = damp_kd, hands in their safe state; terminal: the runtime exits after `damp_s`

Any fault in a commanding phase goes to DAMP: body state older than `max_input_age_periods` control periods or
with a frozen tick, a hand that has not answered its latest request for that long, hand link lost, device error
bits or a reading outside its register's range, motor error bits or over-temperature, another rt/lowcmd
publisher, a mode_machine change, non-finite state, measured joints (body and hands) beyond their limits
(+ margin), non-finite or absurd actions (|a| > action_fault_factor * action_clip), tracker poses stale during
POLICY, IMU and tracker disagreeing on the pelvis tilt, too many loop overruns or one tick more than
`max_stall_periods` late, the watchdog having fired (deploy.watchdog), a silent wireless remote when it is the
e-stop (`remote_estop`), hands commanded below `min_hand_rate_share` of the loop rate, an e-stop, stop or signal. Targets are clamped to the joint limits and
rate limited per tick (`max_target_rate` rad/s) before they are sent; a final check refuses anything outside
the limits.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from deploy.body.base import BodyState
from deploy.contract import PolicyContract
from deploy.hand_pair import HandsReading
from deploy.rotations import tilt_angle_between
from deploy.tracking import TrackedPoses


class Phase(enum.IntEnum):
    WAIT_STATE = 0
    ZERO_TORQUE = 1
    RAMP_TO_DEFAULT = 2
    HOLD = 3
    POLICY = 4
    DAMP = 5


COMMANDING_PHASES = (Phase.ZERO_TORQUE, Phase.RAMP_TO_DEFAULT, Phase.HOLD, Phase.POLICY)


@dataclass
class SafetyConfig:
    max_input_age_periods: float = 2.0  # inputs older than this many control periods -> DAMP
    wait_timeout_s: float = 5.0  # WAIT_STATE gives up (exit, nothing was commanded) after this
    zero_torque_s: float = 0.5
    ramp_s: float = 2.0
    auto_start_after_s: float | None = None  # None: wait for the operator in HOLD
    damp_s: float = 1.0  # DAMP commands are sent this long before the runtime exits
    damp_kd: float = 8.0  # N m s / rad, Unitree's damping-mode gain
    max_target_rate: float = 10.0  # rad/s, per-tick change limit on every joint target
    action_fault_factor: float = 4.0  # |action| beyond factor * action_clip is a broken policy -> DAMP
    joint_limit_margin: float = 0.1  # rad; measured q beyond limits + margin -> DAMP
    max_tilt_mismatch_rad: float | None = 0.35  # IMU vs tracker pelvis tilt; None disables the check
    hand_wait_fraction: float = 0.3  # how long (fraction of a period) a tick waits for last tick's hand exchange
    max_motor_temp_c: float = 90.0  # a body motor at or above this -> refuse the start / DAMP
    max_overruns: int | None = 5  # more loop overruns than this within overrun_window_s -> DAMP (None: count only)
    overrun_window_s: float = 1.0
    max_stall_periods: float | None = 2.0  # one tick ending more than this many periods late -> DAMP
    remote_estop: bool = False  # the wireless remote is the e-stop: it must be reporting to start, and ...
    remote_timeout_s: float = 0.5  # ... silent this long -> DAMP
    watchdog_s: float | None = 0.2  # loop heartbeat silent this long while commanding: the watchdog damps
    min_hand_rate_share: float | None = 0.5  # acknowledged hand commands per s below this share of the loop rate
    hand_rate_window_s: float = 1.0  # ... over this window -> DAMP (None: report only)
    hand_bus_budget_share: float = 0.8  # share of a period one hand link's wire time may fill (start-up check)


def input_faults(
    now: float,
    dt: float,
    config: SafetyConfig,
    contract: PolicyContract,
    body: BodyState | None,
    hands: HandsReading,
    poses: TrackedPoses,
    *,
    need_tracker: bool,
) -> list[str]:
    """Everything wrong with this tick's inputs, as short reasons (empty list: all fresh and sane)."""
    max_age = config.max_input_age_periods * dt
    faults = []
    if body is None:
        faults.append("no body state")
    else:
        if now - body.stamp > max_age:
            faults.append(f"body state stale ({(now - body.stamp) * 1e3:.1f} ms old)")
        if not body.is_finite():
            faults.append("body state not finite")
        else:
            faults.extend(joint_limit_faults(np.concatenate([body.q, hands.rad]), contract, config.joint_limit_margin))
    for side, age in zip(("left", "right"), hands.ages, strict=True):
        if age > max_age * hands.every_n_ticks:  # the hand's own silence since it was asked, not loop lateness
            faults.append(f"{side} hand state stale ({age * 1e3:.1f} ms without an answer)")
    faults.extend(hands.faults)
    faults.extend(remote_faults(now, config, body))
    if need_tracker:
        faults.extend(tracker_faults(now, max_age, contract, poses))
        if config.max_tilt_mismatch_rad is not None and body is not None and body.is_finite() \
                and poses.robot.is_finite():
            tilt = tilt_angle_between(body.imu_quat_wxyz, poses.robot.quat_wxyz)
            if tilt > config.max_tilt_mismatch_rad:
                faults.append(f"IMU and tracker disagree on pelvis tilt by {np.degrees(tilt):.1f} deg")
    return faults


def remote_faults(now: float, config: SafetyConfig, body: BodyState | None) -> list[str]:
    """With the remote as the e-stop, a remote that is not reporting (never, or for remote_timeout_s)."""
    if not config.remote_estop or body is None:
        return []
    if body.remote_stamp is None:
        return ["no wireless remote reporting (it is the e-stop: --remote-estop)"]
    silent = now - body.remote_stamp
    if silent > config.remote_timeout_s:
        return [f"wireless remote silent for {silent * 1e3:.0f} ms (it is the e-stop; limit "
                f"{config.remote_timeout_s * 1e3:.0f} ms)"]
    return []


def joint_limit_faults(q: np.ndarray, contract: PolicyContract, margin: float) -> list[str]:
    """Measured joints (body, then hand channels in actuator order) beyond their limits + margin."""
    beyond = (q < contract.joint_lower - margin) | (q > contract.joint_upper + margin)
    return [f"joint limit breach: {contract.actuator_names[i]} at {q[i]:.3f} rad" for i in np.flatnonzero(beyond)[:1]]


def tracker_faults(now: float, max_age: float, contract: PolicyContract, poses: TrackedPoses) -> list[str]:
    faults = []
    checks = [("robot", poses.robot)]
    if contract.uses_object:
        checks.append(("object", poses.object))
    for name, pose in checks:
        if now - pose.stamp > max_age:
            age = "never seen" if not np.isfinite(pose.stamp) else f"{(now - pose.stamp) * 1e3:.1f} ms old"
            faults.append(f"{name} pose stale ({age})")
        elif not pose.is_finite():
            faults.append(f"{name} pose not finite")
    return faults


def action_fault(action: np.ndarray, contract: PolicyContract, config: SafetyConfig) -> str | None:
    if not np.all(np.isfinite(action)):
        return f"policy action not finite (index {int(np.argmax(~np.isfinite(action)))})"
    limit = config.action_fault_factor * contract.action_clip
    if np.any(np.abs(action) > limit):
        i = int(np.argmax(np.abs(action)))
        return f"policy action out of range: {contract.actuator_names[i]} = {action[i]:.3g} (limit {limit:.3g})"
    return None


def rate_limited(target, previous, max_step):
    """`target` moved at most `max_step` (rad) from `previous`, joint by joint. numpy arrays or torch tensors
    (their shared `clip`): the runtime shapes each tick's targets with it, and students train with the same limit
    (robot_hoi.tasks.interaction.env), so the commands a policy learned with are the ones the robot gets."""
    return previous + (target - previous).clip(-max_step, max_step)


class TargetShaper:
    """Clamp to joint limits, then limit the per-tick change; counts what it had to change by more than
    `report_tolerance` radians (a policy holding a joint at its stop overshoots by micro-radians every tick:
    not worth an event)."""

    report_tolerance = 1e-3

    def __init__(self, contract: PolicyContract, dt: float, max_rate: float):
        self.lower = contract.joint_lower
        self.upper = contract.joint_upper
        self.max_step = max_rate * dt
        self.previous: np.ndarray | None = None
        self.clamped_ticks = 0
        self.rate_limited_ticks = 0
        self.last_clamped: np.ndarray = np.zeros(len(self.lower), dtype=bool)
        self.last_rate_limited: np.ndarray = np.zeros(len(self.lower), dtype=bool)

    def reset(self, current: np.ndarray) -> None:
        """Start rate limiting from `current` (the measured pose when commanding begins)."""
        self.previous = np.clip(np.asarray(current, dtype=np.float64), self.lower, self.upper)

    def __call__(self, target: np.ndarray) -> np.ndarray:
        clamped = np.clip(target, self.lower, self.upper)
        self.last_clamped = np.abs(clamped - target) > self.report_tolerance
        shaped = clamped
        if self.previous is not None:
            shaped = np.clip(rate_limited(clamped, self.previous, self.max_step), self.lower, self.upper)
        self.last_rate_limited = np.abs(shaped - clamped) > self.report_tolerance
        self.clamped_ticks += bool(self.last_clamped.any())
        self.rate_limited_ticks += bool(self.last_rate_limited.any())
        self.previous = shaped
        return shaped


def command_within_limits(q: np.ndarray, kp: np.ndarray, kd: np.ndarray, tau: np.ndarray,
                          contract: PolicyContract) -> bool:
    """Last line of defence before the body: finite, inside joint limits, non-negative gains, |tau| <= effort."""
    n = len(q)
    arrays_ok = all(np.all(np.isfinite(a)) for a in (q, kp, kd, tau))
    return bool(
        arrays_ok
        and np.all(q >= contract.joint_lower[:n])
        and np.all(q <= contract.joint_upper[:n])
        and np.all(kp >= 0)
        and np.all(kd >= 0)
        and np.all(np.abs(tau) <= contract.effort_limit[:n])
    )

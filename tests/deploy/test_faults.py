"""Fault suite on the fake clock: every fault reaches DAMP within one period of being seen, nothing outside the
limits is ever sent, and transient faults the retry/reconnect path absorbs do not stop the robot."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.rotations import quat_wxyz_from_axis_angle
from deploy.safety import Phase, SafetyConfig

from .conftest import RuntimeRig


class SwitchablePolicy:
    """Wraps the dev policy; `override` replaces the next outputs."""

    def __init__(self, inner):
        self.inner = inner
        self.override = None

    def __call__(self, obs):
        out = self.inner(obs)
        return out if self.override is None else np.full_like(out, self.override)


def policy_rig(dev_policy, **safety) -> RuntimeRig:
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(
        zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=0.1, damp_s=safety.pop("damp_s", 0.3), **safety))
    rig.policy = SwitchablePolicy(rig.runtime.policy)
    rig.runtime.policy = rig.policy
    rig.run_until(Phase.POLICY)
    rig.step(5)
    assert rig.runtime.phase == Phase.POLICY
    return rig


def assert_everything_sent_was_safe(rig):
    c = rig.contract
    for cmd in rig.body.commands:
        assert np.all(np.isfinite(cmd["q"])) and np.all(np.isfinite(cmd["kd"]))
        assert np.all(cmd["q"] >= c.joint_lower[:29]) and np.all(cmd["q"] <= c.joint_upper[:29])
        assert np.all(cmd["kp"] >= 0) and np.all(cmd["kd"] >= 0) and np.all(cmd["tau"] == 0)
    for bus in (rig.left, rig.right):
        for units in bus.writes:
            assert np.all(units >= 0) and np.all(units <= 1000)


def tick_once(rig):
    before = len(rig.body.commands)
    rig.step()
    return rig.runtime.phase, rig.body.commands[before] if len(rig.body.commands) > before else None


def assert_damped(rig, command):
    assert rig.runtime.phase == Phase.DAMP
    assert np.all(command["kp"] == 0) and np.all(command["kd"] == rig.safety.damp_kd)


def test_nan_action_damps_in_the_same_tick(dev_policy):
    rig = policy_rig(dev_policy)
    rig.policy.override = np.nan
    phase, command = tick_once(rig)
    assert_damped(rig, command)
    assert "not finite" in rig.runtime.fault_reasons[0]
    assert_everything_sent_was_safe(rig)


def test_absurd_action_damps_in_the_same_tick(dev_policy):
    rig = policy_rig(dev_policy)
    rig.policy.override = 1e6
    phase, command = tick_once(rig)
    assert_damped(rig, command)
    assert "out of range" in rig.runtime.fault_reasons[0]
    assert_everything_sent_was_safe(rig)


def test_out_of_clip_action_is_clipped_clamped_and_rate_limited(dev_policy):
    rig = policy_rig(dev_policy)
    rig.policy.override = 3.0 * rig.contract.action_clip  # beyond the clip, below the fault limit
    previous = rig.body.commands[-1]["q"]
    phase, command = tick_once(rig)
    assert phase == Phase.POLICY
    step = rig.safety.max_target_rate * rig.dt
    assert np.all(np.abs(command["q"] - previous) <= step + 1e-9)
    rig.step(60)
    assert rig.runtime.phase == Phase.POLICY
    np.testing.assert_allclose(rig.body.commands[-1]["q"][3], rig.contract.joint_upper[3])  # knee pinned at limit
    assert rig.runtime.shaper.clamped_ticks > 0 and rig.events.of_kind("shaping")
    assert_everything_sent_was_safe(rig)


def test_hand_timeout_after_retries_damps_within_one_period(dev_policy):
    rig = policy_rig(dev_policy)
    rig.left.fail_calls = 10**6  # the hand stops answering; reconnect fails too
    phase, _ = tick_once(rig)  # this tick's hand exchange is the one that fails
    assert phase == Phase.POLICY and rig.hands.sides[0].link_lost
    phase, command = tick_once(rig)  # the next tick sees it
    assert_damped(rig, command)
    assert any("left hand link lost" in r for r in rig.runtime.fault_reasons)
    assert rig.hands.stats()["left"]["link_errors"] == 1
    assert_everything_sent_was_safe(rig)


def test_transient_hand_error_is_reconnected_without_stopping(dev_policy):
    rig = policy_rig(dev_policy)
    rig.right.fail_calls = 1  # one exhausted request, then the link works again after a reconnect
    rig.step(10)
    assert rig.runtime.phase == Phase.POLICY
    stats = rig.hands.stats()["right"]
    assert stats["link_errors"] == 1 and stats["reconnects"] == 1 and rig.right.reconnects == 1
    assert rig.right.configured is not None
    assert_everything_sent_was_safe(rig)


def test_disconnect_then_reconnect_restores_the_safe_pose(dev_policy):
    rig = policy_rig(dev_policy, damp_s=3.0)
    held = rig.left.writes[-1].copy()
    rig.left.unplugged = True
    rig.step(2)
    assert rig.runtime.phase == Phase.DAMP
    writes_before = len(rig.left.writes)
    rig.step(5)
    assert len(rig.left.writes) == writes_before  # nothing gets through while unplugged
    rig.left.unplugged = False
    rig.left.angles[:] = 1000  # e.g. the hand rebooted open
    rig.step(int(0.6 / rig.dt))  # longer than the reconnect interval
    assert rig.hands.sides[0].link_lost is None and rig.hands.stats()["left"]["reconnects"] >= 1
    np.testing.assert_array_equal(rig.left.writes[-1], held)  # hold: the last safe pose is asserted again
    assert rig.runtime.phase == Phase.DAMP  # DAMP is terminal
    assert_everything_sent_was_safe(rig)


def test_open_safe_state_opens_the_hands(dev_policy):
    rig = RuntimeRig(dev_policy)
    from deploy.hand_pair import Hands

    rig.hands = Hands(rig.left, rig.right, rig.contract.hands, clock=rig.clock, threaded=False, safe_state="open")
    rig.runtime.hands = rig.hands
    rig.hands.connect()
    rig.run_until(Phase.POLICY)
    rig.step(20)
    rig.runtime.request_estop()
    rig.step(2)
    np.testing.assert_array_equal(rig.left.writes[-1], [1000] * 6)
    np.testing.assert_array_equal(rig.right.writes[-1], [1000] * 6)


def test_hand_error_bits_damp_and_get_cleared(dev_policy):
    rig = policy_rig(dev_policy, damp_s=2.0)
    rig.right.error_bits[1] = 0b0001  # locked rotor on the ring finger
    rig.step(1)
    phase, command = tick_once(rig)
    assert_damped(rig, command)
    assert "right hand fault" in rig.runtime.fault_reasons[0]
    rig.step(int(0.6 / rig.dt))
    assert rig.right.clear_count >= 2  # once at connect, then while damped
    assert_everything_sent_was_safe(rig)


@pytest.mark.parametrize("fault", ["object pose", "robot pose", "body state"])
def test_stale_input_damps_within_one_period_of_going_stale(dev_policy, fault):
    rig = policy_rig(dev_policy)
    if fault == "body state":
        rig.body.freeze()
    else:
        rig.tracker.drop(fault.split()[0])
    limit = rig.safety.max_input_age_periods * rig.dt
    if fault == "body state":
        stamp = rig.body.read_state().stamp
    else:
        stamp = getattr(rig.tracker.read(), fault.split()[0]).stamp
    for _ in range(10):
        stale = rig.clock.now() - stamp > limit  # the same test the runtime makes
        phase, command = tick_once(rig)
        if stale:
            break
        assert phase == Phase.POLICY
    assert_damped(rig, command)
    assert f"{fault} stale" in rig.runtime.fault_reasons[0]
    assert_everything_sent_was_safe(rig)


def test_nan_body_state_damps(dev_policy):
    rig = policy_rig(dev_policy)
    rig.body.inject_nan()
    phase, command = tick_once(rig)
    assert_damped(rig, command)
    assert rig.runtime.fault_reasons == ["body state not finite"]
    assert_everything_sent_was_safe(rig)


def test_joint_limit_breach_damps(dev_policy):
    rig = policy_rig(dev_policy)
    rig.body.q[3] = rig.contract.joint_upper[3] + 0.5
    rig.body.kp[:] = 0  # keep it there for the read
    phase, command = tick_once(rig)
    assert_damped(rig, command)
    assert "joint limit breach: left_knee_joint" in rig.runtime.fault_reasons[0]
    assert_everything_sent_was_safe(rig)


def test_imu_disagreeing_with_tracker_damps(dev_policy):
    rig = policy_rig(dev_policy)
    rig.body.imu_quat_source = lambda: quat_wxyz_from_axis_angle(np.array([1.0, 0, 0]), 0.6)
    phase, command = tick_once(rig)
    assert_damped(rig, command)
    assert "disagree on pelvis tilt" in rig.runtime.fault_reasons[0]


def test_tracker_loss_before_start_blocks_the_start(dev_policy):
    rig = RuntimeRig(dev_policy)
    rig.tracker.drop("object")
    rig.step(40)
    assert rig.runtime.phase == Phase.HOLD  # not DAMP: the tracker is not used before the policy
    assert "object pose stale" in rig.events.of_kind("start_refused")[0]["reason"]
    rig.tracker.restore("object")
    rig.step(2)
    assert rig.runtime.phase == Phase.POLICY


def test_body_send_failure_damps_at_the_next_tick(dev_policy):
    rig = policy_rig(dev_policy)
    real_send = rig.body.send
    failures = {"n": 1}

    def flaky_send(*args):
        if failures["n"] > 0:
            failures["n"] -= 1
            from deploy.errors import BodyLinkError

            raise BodyLinkError("DDS write failed")
        return real_send(*args)

    rig.body.send = flaky_send
    rig.step()
    phase, command = tick_once(rig)
    assert_damped(rig, command)
    assert rig.runtime.fault_reasons == ["body send failed: DDS write failed"]
    assert rig.runtime.body_send_errors == 1


def test_shaper_reports_only_changes_beyond_a_milliradian(dev_policy):
    from deploy.safety import TargetShaper

    contract = RuntimeRig(dev_policy).contract
    shaper = TargetShaper(contract, dt=0.02, max_rate=10.0)  # 0.2 rad per tick
    lower, upper = contract.joint_lower, contract.joint_upper
    target = (lower + upper) / 2
    target[3] = upper[3]
    shaper.reset(target)
    target[3] = upper[3] + 2e-6  # a policy holding the knee at its stop, micro-radians past it
    np.testing.assert_array_equal(shaper(target)[3], upper[3])
    assert shaper.clamped_ticks == 0 and not shaper.last_clamped.any()
    target[3] = upper[3] + 0.05
    shaper(target)
    assert shaper.clamped_ticks == 1 and np.flatnonzero(shaper.last_clamped).tolist() == [3]
    target[5] = target[5] + 0.5  # beyond one tick's 0.2 rad
    shaped = shaper(target)
    assert shaper.rate_limited_ticks == 1 and np.flatnonzero(shaper.last_rate_limited).tolist() == [5]
    assert abs(shaped[5] - (target[5] - 0.3)) < 1e-12


def test_rate_limited_is_one_rule_for_numpy_and_torch():
    """The runtime's per-tick limit (numpy) and the students' training env (torch tensors) share deploy.safety's
    rate_limited: each joint moves at most max_step toward its target."""
    import torch

    from deploy.safety import rate_limited

    previous, target = np.array([0.0, 1.0, -1.0]), np.array([0.5, 0.9, -2.0])
    expected = np.array([0.2, 0.9, -1.2])
    np.testing.assert_allclose(rate_limited(target, previous, 0.2), expected)
    shaped = rate_limited(torch.tensor(target)[None], torch.tensor(previous)[None], 0.2)
    np.testing.assert_allclose(shaped[0].numpy(), expected)


def test_the_shaper_applies_the_tighter_of_the_safety_and_the_trained_rate_limit(rig):
    """A policy trained under a target rate limit (its task's command_rate_limit) gets its commands shaped as in
    training when that limit is tighter than the runtime's; a looser or absent one leaves the safety limit."""
    import dataclasses

    from deploy.loop import Runtime
    from deploy.observations import ObservationBuilder
    from deploy.operator import OperatorInput

    assert rig.contract.trained_rate_limit is None
    assert rig.runtime.shaper.max_step == pytest.approx(10.0 * rig.dt)
    for limit, expected in ((6.0, 6.0), (25.0, 10.0)):
        contract = dataclasses.replace(rig.contract, task={"env": {"command_rate_limit": limit}})
        assert contract.trained_rate_limit == limit
        runtime = Runtime(contract, rig.policy, ObservationBuilder(contract, rig.motion), rig.body, rig.tracker,
                          rig.hands, clock=rig.clock, safety=rig.safety, operator=OperatorInput(), events=rig.events)
        assert runtime.shaper.max_step == pytest.approx(expected * rig.dt)

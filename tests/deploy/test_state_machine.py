"""The safety state machine and the loop's timing, driven by a fake clock and fake IO."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.hand_units import rad_to_units
from deploy.operator import ScriptedOperator
from deploy.safety import Phase, SafetyConfig

from .conftest import RuntimeRig


def phases_and_commands(rig, ticks):
    out = []
    for _ in range(ticks):
        before = len(rig.body.commands)
        keep = rig.runtime.tick()
        sent = rig.body.commands[before:]
        out.append((rig.runtime.phase, sent[-1] if sent else None))
        rig.clock.advance(rig.dt)
        if not keep:
            break
    return out


def test_phases_in_order_with_auto_start(rig):
    trace = phases_and_commands(rig, 40)
    phases = [p for p, _ in trace]
    order = [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p]
    assert order == [Phase.ZERO_TORQUE, Phase.RAMP_TO_DEFAULT, Phase.HOLD, Phase.POLICY]
    zero = [c for p, c in trace if p == Phase.ZERO_TORQUE]
    assert zero and all(np.all(c["kp"] == 0) and np.all(c["kd"] == 0) for c in zero)
    assert len(zero) * rig.dt >= rig.safety.zero_torque_s - 1e-9
    ramp = [c for p, c in trace if p == Phase.RAMP_TO_DEFAULT]
    np.testing.assert_allclose(ramp[0]["q"], 0.0, atol=1e-12)  # starts where the body is (all zeros)
    np.testing.assert_array_equal(ramp[0]["kp"], rig.contract.kp[:29])
    default = rig.contract.default_pose[:29]
    steps = np.diff(np.stack([c["q"] for c in ramp] + [default]), axis=0)
    assert np.all(steps * np.sign(default) >= -1e-12), "ramp must move monotonically toward the default pose"
    hold = [c for p, c in trace if p == Phase.HOLD]
    np.testing.assert_allclose(hold[-1]["q"], default)


def test_policy_follows_the_reference(rig):
    rig.run_until(Phase.POLICY)
    rig.step(30)
    motion, contract = rig.motion, rig.contract
    command = rig.body.commands[-1]
    t = rig.runtime.policy_tick
    expected = np.clip(motion.joint_pos[min(t + 1, motion.num_frames - 1)], contract.joint_lower, contract.joint_upper)
    np.testing.assert_allclose(command["q"], expected[:29], atol=1e-5)
    units = rad_to_units(expected[29:], rig.hands.open_rad, rig.hands.closed_rad)
    np.testing.assert_array_equal(np.concatenate([rig.left.writes[-1], rig.right.writes[-1]]), units)
    assert rig.runtime.policy_steps == 31


def test_operator_gates_zero_torque_and_hold(dev_policy):
    safety = SafetyConfig(zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=None, damp_s=0.2)
    t0 = 1000.0
    # confirm in ZERO_TORQUE (stiffen), a press during the ramp (ignored), then one in HOLD (start the policy)
    script = [(t0 + 1.0, "start"), (t0 + 1.2, "start"), (t0 + 2.0, "start")]
    rig = RuntimeRig(dev_policy, safety=safety)
    rig.runtime.operator = ScriptedOperator(rig.clock, script)
    trace = phases_and_commands(rig, 80)
    phases = [p for p, _ in trace]
    limp = [c for p, c in trace if p == Phase.ZERO_TORQUE]
    assert len(limp) * rig.dt >= 1.0 - rig.dt  # held limp until the operator confirmed, long after zero_torque_s
    assert all(np.all(c["kp"] == 0) and np.all(c["kd"] == 0) for c in limp)
    first_policy = phases.index(Phase.POLICY)
    assert first_policy * rig.dt + t0 >= t0 + 2.0 - rig.dt and phases[first_policy - 1] == Phase.HOLD
    assert rig.events.of_kind("start_ignored")[0]["phase"] == "RAMP_TO_DEFAULT"
    reasons = [e["reason"] for e in rig.events.of_kind("phase")]
    assert reasons[1].startswith("operator confirmed") and reasons[-1] == "operator start"
    assert [e["phase"] for e in rig.events.of_kind("prompt")] == ["ZERO_TORQUE", "HOLD"]


def test_zero_torque_never_ends_without_a_confirmation(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(zero_torque_s=0.1, auto_start_after_s=None))
    rig.step(int(10 / rig.dt))
    assert rig.runtime.phase == Phase.ZERO_TORQUE and "stiffen" in rig.runtime.prompt
    assert all(np.all(c["kp"] == 0) and np.all(c["kd"] == 0) for c in rig.body.commands)
    rig.runtime.request_start()  # the keyboard / remote hook
    rig.step(1)
    assert rig.runtime.phase == Phase.RAMP_TO_DEFAULT and rig.runtime.prompt is None


def test_estop_damps_then_exits(rig):
    rig.run_until(Phase.POLICY)
    rig.step(5)
    last_policy_units = rig.left.writes[-1].copy()
    rig.runtime.request_estop("operator e-stop")
    trace = phases_and_commands(rig, 30)
    assert trace[0][0] == Phase.DAMP
    damp = [c for p, c in trace if p == Phase.DAMP]
    assert all(np.all(c["kp"] == 0) and np.all(c["kd"] == rig.safety.damp_kd) for c in damp)
    assert len(trace) == pytest.approx(rig.safety.damp_s / rig.dt + 1, abs=1)  # then tick() returns False
    np.testing.assert_array_equal(rig.left.writes[-1], last_policy_units)  # hold: last pose asserted again
    assert "operator e-stop" in rig.runtime.exit_reason
    assert rig.runtime.fault_reasons == []


def test_second_estop_never_shortens_damping(rig):
    rig.run_until(Phase.HOLD)
    rig.runtime.request_estop("remote e-stop")
    rig.runtime.request_estop("operator e-stop")
    before = len(rig.body.commands)
    while rig.runtime.tick():
        rig.clock.advance(rig.dt)
    assert rig.runtime.phase == Phase.DAMP and rig.runtime.exit_reason.startswith("remote e-stop")
    damped = rig.body.commands[before:]
    assert len(damped) >= round(rig.safety.damp_s / rig.dt) and all(np.all(c["kp"] == 0) for c in damped)


def test_wait_state_times_out_without_commanding(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(wait_timeout_s=0.5))
    rig.body.freeze()  # no state ever arrives
    rig.body._last_state = None
    summary = rig.runtime.run(duration_s=5.0)
    assert rig.body.commands == []
    assert summary["final_phase"] == "WAIT_STATE"
    assert "no body state" in summary["exit_reason"]
    assert rig.clock.now() - 1000.0 == pytest.approx(0.5 + rig.dt, abs=rig.dt)


def test_run_sleeps_to_absolute_deadlines_and_counts_overruns(dev_policy):
    rig = RuntimeRig(dev_policy)
    inner = rig.policy
    calls = {"n": 0}

    def slow_policy(obs):
        calls["n"] += 1
        rig.clock.advance(0.004)  # compute time
        if calls["n"] == 10:
            rig.clock.advance(2.5 * rig.dt)  # one long stall: two deadlines are missed
        return inner(obs)

    rig.runtime.policy = slow_policy
    start = rig.clock.now()
    summary = rig.runtime.run(duration_s=2.0)
    sleeps = np.array(rig.clock.sleeps) - start
    k = sleeps / rig.dt
    np.testing.assert_allclose(k, np.round(k), atol=1e-6)  # every wake-up is on the start + k*dt grid
    assert np.all(np.diff(k) >= 1 - 1e-6)
    assert summary["overruns"] == 1 and summary["missed_deadlines"] == 2
    assert summary["lateness_ms"]["max"] == pytest.approx(0.0, abs=1e-6)  # fake clock wakes exactly
    assert summary["compute_ms"]["max"] > 2.5 * rig.dt * 1e3
    assert summary["final_phase"] == "DAMP" and "duration reached" in summary["exit_reason"]
    assert summary["faults"] == []


def test_stop_request_ends_through_damp(dev_policy):
    rig = RuntimeRig(dev_policy)
    rig.runtime.operator = ScriptedOperator(rig.clock, [(1000.0 + 1.0, "stop")])
    summary = rig.runtime.run(duration_s=10.0)
    assert summary["exit_reason"].startswith("operator stop")
    assert summary["phase_time_s"]["DAMP"] == pytest.approx(rig.safety.damp_s, abs=rig.dt)
    assert rig.clock.now() < 1000.0 + 2.0


def test_hands_exchanged_once_per_tick_through_every_phase(rig):
    """At the planned rate (every tick here) each hand gets one exchange per control tick, policy phase included; the
    real-time dry run only checks it loosely, since a starved hand thread lags there."""
    ticks = rig.run_until(Phase.POLICY) + 30
    rig.step(30)
    stats = rig.hands.stats()
    assert stats["left"]["cycles"] == ticks and stats["right"]["cycles"] == ticks

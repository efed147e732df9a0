"""Field-grade checks on the fake clock: robot identity and LowState health, the wireless remote, outcomes and exit
codes, loop overruns, and hand staleness judged apart from the loop's own lateness."""

from __future__ import annotations

import signal

import numpy as np
import pytest

from deploy.outcome import Outcome
from deploy.remote import RemotePresses, keys_from_wireless_remote, keys_of, wireless_remote_bytes
from deploy.safety import Phase, SafetyConfig

from .conftest import RuntimeRig

GATED = dict(zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=None, damp_s=0.2)


def policy_rig(dev_policy, **safety) -> RuntimeRig:
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=0.1,
                                                     damp_s=0.2, **safety))
    rig.runtime.expected_mode_machine = 5
    rig.run_until(Phase.POLICY)
    rig.step(3)
    return rig


def assert_damped_with(rig, text):
    rig.step(1)
    assert rig.runtime.phase == Phase.DAMP, rig.runtime.fault_reasons
    assert any(text in r for r in rig.runtime.fault_reasons), rig.runtime.fault_reasons
    assert np.all(rig.body.commands[-1]["kp"] == 0)


# ------------------------------------------------------------------ robot identity
@pytest.mark.parametrize("setup,expected", [
    (lambda b: setattr(b, "mode_machine", 4), "mode_machine 4 (G1 23-DoF rev 1.0); the policy is for 5"),
    (lambda b: setattr(b, "other_commanders", 1), "other rt/lowcmd publisher"),
    (lambda b: b.motor_error.__setitem__(3, 0x20), "motor error: left_knee_joint motorstate 0x00000020"),
    (lambda b: b.motor_temp_c.__setitem__(12, 95.0), "motor over temperature: waist_yaw_joint at 95 C"),
])
def test_wrong_or_unhealthy_robot_is_refused_before_anything_is_commanded(dev_policy, setup, expected):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**GATED))
    rig.runtime.expected_mode_machine = 5
    setup(rig.body)
    summary = rig.runtime.run(duration_s=5.0)
    assert rig.body.commands == []
    assert summary["outcome"] == "REFUSED" and summary["exit_code"] == 4
    assert expected in summary["exit_reason"] and "nothing commanded" in summary["exit_reason"]


def test_identity_fault_in_zero_torque_refuses_without_stiffening(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**GATED))
    rig.runtime.expected_mode_machine = 5
    rig.run_until(Phase.ZERO_TORQUE)
    rig.body.other_commanders = 1  # DDS discovery found sport mode a moment later
    rig.step(1)
    assert rig.runtime.phase == Phase.DAMP and rig.runtime.outcome == Outcome.REFUSED
    assert all(np.all(c["kp"] == 0) for c in rig.body.commands)


@pytest.mark.parametrize("change,expected", [
    (lambda b: setattr(b, "mode_machine", 6), "robot reports mode_machine 6"),
    (lambda b: setattr(b, "other_commanders", 2), "2 other rt/lowcmd publisher(s)"),
    (lambda b: b.motor_error.__setitem__(0, 1), "motor error: left_hip_pitch_joint"),
    (lambda b: b.motor_temp_c.__setitem__(5, 90.0), "motor over temperature: left_ankle_roll_joint"),
])
def test_identity_or_health_change_while_commanding_damps(dev_policy, change, expected):
    rig = policy_rig(dev_policy)
    change(rig.body)
    assert_damped_with(rig, expected)
    assert rig.runtime.outcome == Outcome.FAULT


def test_frozen_tick_damps_although_states_keep_arriving(dev_policy):
    rig = policy_rig(dev_policy)
    rig.body.tick_frozen = True
    limit = rig.safety.max_input_age_periods * rig.dt
    for _ in range(int(limit / rig.dt) + 2):
        rig.step(1)
        if rig.runtime.phase == Phase.DAMP:
            break
    assert any("body tick frozen" in r for r in rig.runtime.fault_reasons)
    assert not any("body state stale" in r for r in rig.runtime.fault_reasons)


# ------------------------------------------------------------------ the wireless remote
def test_remote_bytes_and_presses():
    raw = wireless_remote_bytes(keys_of("START", "L2"))
    assert len(raw) == 40 and keys_from_wireless_remote(raw) == keys_of("START", "L2")
    presses = RemotePresses()
    t = iter(0.1 * i for i in range(100))
    assert presses.update(keys_of("B"), next(t)) == []  # held at start-up: the baseline, not a press
    assert presses.update(keys_of("B"), next(t)) == []
    assert presses.update(0, next(t)) == []
    assert presses.update(keys_of("START"), next(t)) == []  # no single button starts anything
    assert presses.update(keys_of("L1", "A"), next(t)) == []  # the chord, just pressed
    assert presses.update(keys_of("L1", "A"), next(t) + 0.5) == ["start"]  # ... held 0.5 s
    assert presses.update(keys_of("L1", "A"), next(t) + 0.5) == []  # once per hold
    assert presses.update(keys_of("SELECT"), next(t) + 0.5) == ["stop"]
    assert presses.update(keys_of("SELECT", "B"), next(t) + 0.5) == ["estop"]


def press(rig, *buttons, hold_s=0.0):
    rig.body.remote_keys = keys_of(*buttons)
    rig.step(1 + round(hold_s / rig.dt) + (hold_s > 0))  # held a tick beyond hold_s
    rig.body.remote_keys = 0
    rig.step(2)


def test_remote_start_confirms_both_gates(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**GATED))
    rig.step(20)
    assert rig.runtime.phase == Phase.ZERO_TORQUE
    press(rig, "L1", "A", hold_s=0.5)
    assert rig.runtime.phase == Phase.RAMP_TO_DEFAULT
    rig.run_until(Phase.HOLD)
    rig.step(10)
    assert rig.runtime.phase == Phase.HOLD
    press(rig, "L1", "A", hold_s=0.5)
    assert rig.runtime.phase == Phase.POLICY
    assert [e["source"] for e in rig.events.of_kind("operator")] == ["remote", "remote"]


@pytest.mark.parametrize("button,outcome,reason", [("B", Outcome.ESTOP, "remote e-stop"),
                                                   ("SELECT", Outcome.COMPLETED, "remote stop")])
def test_remote_stop_and_estop(dev_policy, button, outcome, reason):
    rig = policy_rig(dev_policy)
    press(rig, button)
    assert rig.runtime.phase == Phase.DAMP
    rig.step(20)
    assert rig.runtime.outcome == outcome and reason in rig.runtime.exit_reason


# ------------------------------------------------------------------ outcomes and stop requests
def test_outcomes_of_runs_that_never_ran_the_policy(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(wait_timeout_s=0.5))
    rig.body.freeze()
    rig.body._last_state = None
    assert rig.runtime.run(duration_s=5.0)["outcome"] == "NOT_STARTED"

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**GATED))
    summary = rig.runtime.run(duration_s=1.0)  # nobody confirmed: ends limp in ZERO_TORQUE -> DAMP
    assert summary["policy_steps"] == 0 and summary["exit_code"] == 3 and summary["faults"] == []


def test_duration_in_policy_completes_with_code_0(dev_policy):
    summary = RuntimeRig(dev_policy).runtime.run(duration_s=2.0)
    assert summary["policy_steps"] > 0 and summary["outcome"] == "COMPLETED" and summary["exit_code"] == 0


@pytest.mark.parametrize("signum,outcome", [(signal.SIGTERM, "SIGTERM"), (signal.SIGHUP, "SIGHUP"),
                                            (signal.SIGINT, "COMPLETED")])
def test_signals_damp_and_say_why(dev_policy, signum, outcome):
    rig = policy_rig(dev_policy)
    rig.runtime.request_signal(signum)
    rig.step(20)
    summary = rig.runtime.summary()
    assert summary["final_phase"] == "DAMP" and summary["outcome"] == outcome
    assert summary["exit_reason"].startswith(signal.Signals(signum).name)
    assert summary["exit_code"] == (0 if signum == signal.SIGINT else 128 + signum)


def test_second_signal_aborts_with_a_reason(dev_policy):
    rig = policy_rig(dev_policy)
    rig.runtime.request_signal(signal.SIGINT)
    rig.runtime.request_signal(signal.SIGINT)
    assert rig.runtime.tick() is False
    assert rig.runtime.exit_reason == "SIGINT twice: aborted after one damping command"
    assert rig.runtime.outcome == Outcome.SIGINT and rig.runtime.outcome.code == 130


# ------------------------------------------------------------------ loop timing and hand staleness
def test_too_many_overruns_damp(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=0.1,
                                                     damp_s=0.2, max_overruns=3, overrun_window_s=1.0))
    inner = rig.policy

    def slow(obs):
        rig.clock.advance(1.5 * rig.dt)  # every policy step overruns its period
        return inner(obs)

    rig.runtime.policy = slow
    summary = rig.runtime.run(duration_s=5.0)
    assert summary["faults"][0] == "loop overran 4 deadlines within 1 s (limit 3)"
    assert summary["overruns"] >= 4 and summary["outcome"] == "FAULT"


def test_a_late_loop_wakeup_is_not_blamed_on_the_hands(dev_policy):
    rig = policy_rig(dev_policy)
    rig.clock.advance(5 * rig.dt)  # the loop sleeps through several periods; the hands had answered
    rig.step(1)
    assert rig.runtime.phase == Phase.POLICY, rig.runtime.fault_reasons
    assert rig.hands.finish_cycle().ages.tolist() == [0.0, 0.0]


def test_a_hand_that_stops_answering_is_stale_from_its_own_request(dev_policy):
    rig = policy_rig(dev_policy)
    side = rig.hands.sides[1]
    asked = rig.clock.now()
    side.asked_at, side.stamp = asked, asked - 0.5  # asked now, last answer long ago (e.g. exchange still pending)
    assert side.age(asked + 0.01) == pytest.approx(0.01)  # its own silence, not the 0.5 s since the last answer

"""The runtime against the simulated Inspire hands speaking real bytes (serial frames, Modbus RTU, CAN), in real
time: byte-level faults the bus retries are absorbed; persistent ones, a disconnect and device error bits reach
DAMP, hands hold their pose, and nothing outside the limits is sent."""

from __future__ import annotations

import numpy as np
import pytest

from deploy.body.simulated import SimulatedBody
from deploy.clock import MonotonicClock
from deploy.hand_pair import Hands
from deploy.hands import make_hand_bus
from deploy.hands.simulated import start_simulated_hand
from deploy.loop import Runtime
from deploy.motion import load_motion
from deploy.observations import ObservationBuilder
from deploy.policy import OnnxPolicy
from deploy.safety import Phase, SafetyConfig
from deploy.tracking import SimulatedTracker

RATE_HZ = 50.0
BUS_TIMEOUT_S = 0.05  # generous: a loaded CI machine must not turn scheduling delays into faults


class RealTimeRig:
    def __init__(self, dev_policy, transport: str, damp_s: float = 0.4, bus_timeout_s: float = BUS_TIMEOUT_S,
                 max_input_age_periods: float = 8, min_hand_rate_share: float | None = None):
        self.clock = MonotonicClock()
        policy = OnnxPolicy(dev_policy)
        self.contract = policy.contract
        motion = load_motion(self.contract.reference_path())
        self.sims = [start_simulated_hand(transport, side, hand_id=i + 1) for i, side in enumerate(("left", "right"))]
        buses = [make_hand_bus(transport, sim.side, **sim.bus_kwargs(), timeout=bus_timeout_s, retries=2)
                 for sim in self.sims]
        self.hands = Hands(*buses, self.contract.hands, clock=self.clock, threaded=True)
        self.body = SimulatedBody(self.contract.num_body, clock=self.clock)
        self.body.keep_commands = True
        tracker = SimulatedTracker(motion, clock=self.clock)
        self.body.imu_quat_source = tracker.true_robot_quat_wxyz
        # Staleness is tested on the fake clock; here the limit is generous so a busy CI machine cannot trip it.
        # The hand rate share is off unless a test is about it: a starved CI box must not trip it elsewhere.
        self.safety = SafetyConfig(zero_torque_s=0.05, ramp_s=0.1, auto_start_after_s=0.05, damp_s=damp_s,
                                   max_input_age_periods=max_input_age_periods,
                                   min_hand_rate_share=min_hand_rate_share)
        self.body.connect()
        self.hands.connect()
        self.runtime = Runtime(self.contract, policy, ObservationBuilder(self.contract, motion), self.body, tracker,
                               self.hands, clock=self.clock, safety=self.safety, rate_hz=RATE_HZ)
        self.deadline = self.clock.now()
        self.damp_seen_at: float | None = None

    def run(self, seconds: float) -> bool:
        end = self.clock.now() + seconds
        while self.clock.now() < end:
            keep = self.runtime.tick(self.deadline)
            if self.runtime.phase == Phase.DAMP and self.damp_seen_at is None:
                self.damp_seen_at = self.clock.now()
            if not keep:
                return False
            self.deadline += self.runtime.dt
            self.clock.sleep_until(max(self.deadline, self.clock.now()))
        return True

    def to_policy(self):
        for _ in range(100):
            self.run(0.05)
            if self.runtime.phase == Phase.POLICY:
                self.run(0.1)
                return
        raise AssertionError(f"never reached POLICY: {self.runtime.phase}, faults {self.runtime.fault_reasons}")

    def close(self):
        self.hands.close()
        for sim in self.sims:
            sim.stop()

    def assert_safe(self):
        c = self.contract
        for cmd in self.body.commands:
            assert np.all(np.isfinite(cmd["q"]))
            assert np.all(cmd["q"] >= c.joint_lower[:29]) and np.all(cmd["q"] <= c.joint_upper[:29])
        for sim in self.sims:
            for w in sim.writes:
                if w.register == "ANGLE_SET":
                    assert all(0 <= v <= 1000 for v in w.values)


@pytest.fixture(params=["serial", "modbus", "can"])
def transport(request):
    return request.param


@pytest.fixture
def real_rig(dev_policy, transport):
    rig = RealTimeRig(dev_policy, transport)
    yield rig
    rig.close()


@pytest.fixture
def patient_rig(dev_policy, transport):
    """Long bus timeouts and a 1 s staleness limit: only the retry path is under test, not the machine's load."""
    rig = RealTimeRig(dev_policy, transport, bus_timeout_s=0.06, max_input_age_periods=50)
    yield rig
    rig.close()


def _retries(rig, side=0):
    return rig.hands.stats()[("left", "right")[side]].get("bus_retries", 0)


def test_transient_byte_faults_are_retried_without_stopping(patient_rig, transport):
    rig = patient_rig
    rig.to_policy()
    sim = rig.sims[0]
    faults = [sim.drop_next, sim.corrupt_checksum_next, sim.garble_next, sim.partial_next]
    if transport == "can":
        faults.append(sim.error_frame_next)
    for inject in faults:
        before = _retries(rig)
        inject(1)
        for _ in range(10):  # a loaded machine may need a few more ticks before the faulty reply and its retry
            rig.run(0.1)
            if _retries(rig) > before and not sim.pending_faults():
                break
        assert rig.runtime.phase == Phase.POLICY, (inject.__name__, rig.runtime.fault_reasons)
        if not (transport == "can" and inject.__name__ == "partial_next"):  # a short CAN write ack is accepted
            assert _retries(rig) > before, f"{inject.__name__} was not retried"
    rig.assert_safe()


@pytest.mark.parametrize("fault", ["drop_next", "corrupt_checksum_next", "garble_next", "partial_next"])
def test_persistent_byte_faults_reach_damp(dev_policy, transport, fault):
    rig = RealTimeRig(dev_policy, transport)
    try:
        rig.to_policy()
        held = rig.hands.sides[1].last_sent.copy()
        injected_at = rig.clock.now()
        getattr(rig.sims[1], fault)(10_000)
        rig.run(0.5)
        assert rig.damp_seen_at is not None, rig.runtime.fault_reasons
        # bus: 3 tries + a reconnect (3 more tries) = 0.3 s, then one period to act on it; slack for a busy CI box
        assert rig.damp_seen_at - injected_at < 0.6
        # the link-lost report, or (when the machine is slow) the staleness check, whichever fires first
        assert any(r.startswith("right hand") for r in rig.runtime.fault_reasons), rig.runtime.fault_reasons
        assert np.array_equal(rig.sims[1].model.commanded_angles, held)  # the hand keeps its last pose
        rig.assert_safe()
    finally:
        rig.close()


def test_disconnect_reaches_damp_and_reconnect_restores_the_link(dev_policy, transport):
    rig = RealTimeRig(dev_policy, transport, damp_s=2.0)
    try:
        rig.to_policy()
        held = rig.hands.sides[0].last_sent.copy()
        rig.sims[0].disconnect()
        rig.run(0.4)
        assert rig.runtime.phase == Phase.DAMP
        assert any("left hand" in r for r in rig.runtime.fault_reasons)
        rig.sims[0].reconnect()
        rig.run(1.0)
        side = rig.hands.sides[0]
        assert side.link_lost is None and side.stats.reconnects >= 1
        assert np.array_equal(rig.sims[0].model.commanded_angles, held)
        assert rig.runtime.phase == Phase.DAMP
        rig.assert_safe()
    finally:
        rig.close()


def test_device_error_bits_reach_damp(real_rig):
    rig = real_rig
    rig.to_policy()
    rig.sims[0].set_error_bits(0b0100, fingers=[3], sticky=True)  # over-current on the index finger
    rig.run(0.3)
    assert rig.runtime.phase == Phase.DAMP
    assert rig.hands.sides[0].device_fault is not None and "over-current" in rig.hands.sides[0].device_fault
    rig.assert_safe()


def test_can_error_frames_persisting_reach_damp(dev_policy):
    rig = RealTimeRig(dev_policy, "can")
    try:
        rig.to_policy()
        rig.sims[0].error_frame_next(10_000)
        rig.run(0.5)
        assert rig.runtime.phase == Phase.DAMP
        assert any(r.startswith("left hand") for r in rig.runtime.fault_reasons), rig.runtime.fault_reasons
        rig.assert_safe()
    finally:
        rig.close()


@pytest.mark.parametrize("register,value,expected", [
    ("ANGLE_ACT", 4000, "index ANGLE_ACT = 4000 (valid 0..1000)"),  # a firmware glitch
    ("FORCE_ACT", -6141, "index FORCE_ACT = -6141 (valid -4000..4000)"),  # 1000 with its bytes swapped
])
def test_out_of_range_reading_is_a_named_fault_and_never_reaches_the_observation(real_rig, register, value,
                                                                                   expected):
    rig = real_rig
    rig.to_policy()
    rig.sims[1].override_reading(register, 3, value)
    rig.run(0.3)
    assert rig.runtime.phase == Phase.DAMP
    assert any(r.startswith("right hand reading out of range") and expected in r
               for r in rig.runtime.fault_reasons), rig.runtime.fault_reasons
    reading = rig.hands.finish_cycle()
    assert reading.angles.max() <= 1000 and reading.forces.min() >= -4000  # the bad value was dropped
    rig.assert_safe()


def test_slow_hand_replies_fall_below_the_hand_rate_share(dev_policy):
    """Every reply 10 ms late (4 transactions a cycle): the hand is commanded far below the 50 Hz loop rate."""
    rig = RealTimeRig(dev_policy, "serial", max_input_age_periods=50, min_hand_rate_share=0.5)
    try:
        for sim in rig.sims:
            sim.turnaround_s = 0.010
        rig.to_policy()
        rig.run(1.5)
        assert rig.runtime.phase == Phase.DAMP
        assert any("hand commanded at" in r and "below 50% of the 50 Hz loop" in r
                   for r in rig.runtime.fault_reasons), rig.runtime.fault_reasons
        rates = rig.runtime.summary()["hands"]
        assert all(entry["command_rate_hz"] < 25 for entry in rates.values())
    finally:
        rig.close()

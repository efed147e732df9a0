"""Fakes and fixtures for the runtime tests: an in-memory HandBus and a runtime wired to a fake clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from deploy.body.simulated import SimulatedBody
from deploy.clock import FakeClock
from deploy.contract import PolicyContract
from deploy.devpolicy import build_dev_policy
from deploy.errors import HandFaultError, HandLinkError
from deploy.hand_pair import Hands
from deploy.loop import Runtime
from deploy.motion import load_motion
from deploy.observations import ObservationBuilder
from deploy.operator import OperatorInput
from deploy.policy import OnnxPolicy
from deploy.runlog import EventLog, TickRecorder
from deploy.safety import SafetyConfig
from deploy.tracking import SimulatedTracker

REPO = Path(__file__).resolve().parents[2]
EMBODIMENT_YAML = REPO / "configs" / "embodiments" / "g1_inspire.yaml"


class FakeHandState:
    def __init__(self, angles, forces, errors, stamp):
        self.angles, self.forces, self.errors, self.stamp = angles, forces, errors, stamp
        self.status = np.zeros(6, np.uint8)
        self.temperatures = np.full(6, 30, np.uint8)


class FakeHandBus:
    """HandBus in memory: fingers jump to ANGLE_SET; failures behave like a bus that exhausted its retries."""

    def __init__(self, side: str, clock):
        self.side = side
        self.clock = clock
        self.connected = False
        self.angles = np.full(6, 1000, dtype=np.int64)
        self.forces = np.zeros(6, dtype=np.int64)
        self.error_bits = np.zeros(6, dtype=np.uint8)
        self.writes: list[np.ndarray] = []
        self.configured = None
        self.clear_count = 0
        self.fail_calls = 0  # the next N calls raise HandLinkError
        self.unplugged = False  # every call (and connect) fails until plug()
        self.reconnects = 0

    @property
    def is_connected(self) -> bool:
        return self.connected

    def _link(self, what: str) -> None:
        if self.unplugged:
            raise HandLinkError(f"{self.side} hand: {what}: device disconnected")
        if self.fail_calls > 0:
            self.fail_calls -= 1
            raise HandLinkError(f"{self.side} hand: {what}: no reply after 3 tries (timeout)")

    def connect(self) -> None:
        self._link("connect")
        self.connected = True

    def disconnect(self) -> None:
        self.connected = False

    def reconnect(self) -> None:
        self.connected = False
        self.connect()
        self.reconnects += 1

    def configure(self, force_limits, speeds) -> None:
        self._link("configure")
        self.configured = (list(force_limits), list(speeds))

    def clear_errors(self) -> None:
        self._link("clear_errors")
        self.clear_count += 1
        self.error_bits[:] = 0

    def write_angles(self, units) -> None:
        self._link("write ANGLE_SET")
        units = np.clip(np.rint(np.asarray(units, dtype=float)), 0, 1000).astype(np.int64)
        self.writes.append(units)
        self.angles = units.copy()

    def read_state(self):
        self._link("read state")
        state = FakeHandState(self.angles.copy(), self.forces.copy(), self.error_bits.copy(), self.clock.now())
        if np.any(self.error_bits):
            exc = HandFaultError(f"{self.side} hand: error bits {self.error_bits.tolist()}")
            exc.state = state
            raise exc
        return state


@pytest.fixture(scope="session")
def dev_policy(tmp_path_factory) -> Path:
    """A follow-the-reference dev policy with its motion sidecar (built once per session)."""
    return build_dev_policy(tmp_path_factory.mktemp("policy") / "dev.onnx", embodiment=EMBODIMENT_YAML)


class RuntimeRig:
    """A runtime on a fake clock with the numpy body, the simulated tracker and two in-memory hands."""

    def __init__(self, policy_path: Path, log_dir: Path | None = None, safety: SafetyConfig | None = None,
                 operator=None, policy=None):
        self.clock = FakeClock()
        onnx_policy = OnnxPolicy(policy_path)
        self.contract: PolicyContract = onnx_policy.contract
        self.motion = load_motion(self.contract.reference_path())
        self.policy = policy or onnx_policy
        self.body = SimulatedBody(self.contract.num_body, clock=self.clock)
        self.body.keep_commands = True
        self.tracker = SimulatedTracker(self.motion, clock=self.clock)
        self.body.imu_quat_source = self.tracker.true_robot_quat_wxyz
        self.left = FakeHandBus("left", self.clock)
        self.right = FakeHandBus("right", self.clock)
        self.hands = Hands(self.left, self.right, self.contract.hands, clock=self.clock, threaded=False)
        self.safety = safety or SafetyConfig(zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=0.1, damp_s=0.2)
        self.events = EventLog(self.clock, None if log_dir is None else log_dir / "events.jsonl")
        self.recorder = TickRecorder(log_dir)
        self.body.connect()
        self.tracker.connect()
        self.hands.connect()
        self.runtime = Runtime(self.contract, self.policy, ObservationBuilder(self.contract, self.motion), self.body,
                               self.tracker, self.hands, clock=self.clock, safety=self.safety,
                               operator=operator if operator is not None else OperatorInput(), events=self.events,
                               recorder=self.recorder)
        self.dt = self.runtime.dt

    def step(self, n: int = 1) -> bool:
        """n ticks, each followed by one period of fake time."""
        keep = True
        for _ in range(n):
            keep = self.runtime.tick()
            self.clock.advance(self.dt)
            if not keep:
                break
        return keep

    def run_until(self, phase, max_ticks: int = 500) -> int:
        for i in range(max_ticks):
            if self.runtime.phase == phase:
                return i
            if not self.step():
                break
        assert self.runtime.phase == phase, f"never reached {phase}; stuck in {self.runtime.phase}"
        return max_ticks


@pytest.fixture
def rig(dev_policy):
    return RuntimeRig(dev_policy)

"""A numpy stand-in for the robot body: first-order joint tracking and an IMU (no physics, no mujoco).

Each joint follows its PD target with time constant max(kd / kp, min_time_constant_s); with kp = 0 and kd > 0 its
velocity decays (damping); with kp = kd = 0 it keeps its position (a robot in a gantry). The IMU is upright by
default, or follows `imu_quat_source()` when a simulated world provides the pelvis orientation. Time comes from
the injected clock, so fake-clock tests are exact. Faults can be injected: `freeze()` stops new measurements
(stale state), `inject_nan()` makes the next reading non-finite. It reports what the G1's LowState reports, each
settable on demand: `mode_machine` (5, the 29-DoF rev 1.0), `tick` (advances per reading unless `tick_frozen`),
`motor_error` bits and `motor_temp_c` per joint, `remote_keys` (wireless remote buttons, deploy.remote; its
reports stop while `remote_connected` is False, and its buttons read as none) and `other_commanders` (other
rt/lowcmd publishers).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from deploy.body.base import Body, BodyState
from deploy.clock import Clock, MonotonicClock
from deploy.errors import BodyLinkError

UPRIGHT_WXYZ = np.array([1.0, 0.0, 0.0, 0.0])


class SimulatedBody(Body):
    def __init__(
        self,
        num_joints: int = 29,
        clock: Clock | None = None,
        initial_q: np.ndarray | None = None,
        min_time_constant_s: float = 0.02,
        damping_time_constant_s: float = 0.05,
        imu_quat_source: Callable[[], np.ndarray] | None = None,
    ):
        self.num_joints = num_joints
        self.clock = clock or MonotonicClock()
        self.q = np.zeros(num_joints) if initial_q is None else np.array(initial_q, dtype=np.float64)
        self.dq = np.zeros(num_joints)
        self.min_time_constant_s = min_time_constant_s
        self.damping_time_constant_s = damping_time_constant_s
        self.imu_quat_source = imu_quat_source
        self.target_q = self.q.copy()
        self.kp = np.zeros(num_joints)
        self.kd = np.zeros(num_joints)
        self.connected = False
        self.frozen = False
        self._nan_next = False
        self._last_update: float | None = None
        self._last_state: BodyState | None = None
        self.commands: list[dict[str, np.ndarray]] = []
        self.keep_commands = True
        self.mode_machine = 5
        self.tick = 0
        self.tick_frozen = False
        self.motor_error = np.zeros(num_joints, dtype=np.uint32)
        self.motor_temp_c = np.full(num_joints, 40.0)
        self.remote_keys = 0
        self.remote_connected = True
        self._remote_stamp: float | None = None
        self.other_commanders = 0

    def connect(self) -> None:
        self.connected = True
        self._last_update = self.clock.now()

    def close(self) -> None:
        self.connected = False

    def freeze(self) -> None:
        """Stop producing new measurements: read_state keeps returning the last (aging) state."""
        self.frozen = True

    def unfreeze(self) -> None:
        self.frozen = False

    def inject_nan(self) -> None:
        self._nan_next = True

    def _integrate(self, now: float) -> None:
        dt = max(0.0, now - (self._last_update if self._last_update is not None else now))
        self._last_update = now
        if dt == 0.0:
            return
        q_old = self.q.copy()
        tracking = self.kp > 0
        tau_c = np.maximum(np.divide(self.kd, self.kp, out=np.zeros_like(self.kd), where=tracking),
                           self.min_time_constant_s)
        alpha = 1.0 - np.exp(-dt / tau_c)
        self.q = np.where(tracking, self.q + alpha * (self.target_q - self.q), self.q)
        damping = (~tracking) & (self.kd > 0)
        decayed = self.dq * np.exp(-dt / self.damping_time_constant_s)
        self.q = np.where(damping, self.q + decayed * dt, self.q)
        self.dq = np.where(tracking, (self.q - q_old) / dt, np.where(damping, decayed, 0.0))

    def read_state(self) -> BodyState | None:
        if not self.connected:
            raise BodyLinkError("simulated body is not connected")
        if self.frozen:
            return self._last_state
        now = self.clock.now()
        self._integrate(now)
        quat = UPRIGHT_WXYZ.copy() if self.imu_quat_source is None else np.asarray(self.imu_quat_source(), float)
        self.tick += 0 if self.tick_frozen else 1
        if self.remote_connected:
            self._remote_stamp = now
        state = BodyState(q=self.q.copy(), dq=self.dq.copy(), imu_quat_wxyz=quat, gyro=np.zeros(3), stamp=now,
                          mode_machine=self.mode_machine, tick=self.tick, motor_error=self.motor_error.copy(),
                          motor_temp_c=self.motor_temp_c.copy(),
                          remote_keys=self.remote_keys if self.remote_connected else 0,
                          remote_stamp=self._remote_stamp,
                          other_commanders=self.other_commanders)
        if self._nan_next:
            state.q[0] = np.nan
            self._nan_next = False
        self._last_state = state
        return state

    def send(self, q: np.ndarray, dq: np.ndarray, kp: np.ndarray, kd: np.ndarray, tau: np.ndarray) -> None:
        if not self.connected:
            raise BodyLinkError("simulated body is not connected")
        self._check_command(q, dq, kp, kd, tau)
        self._integrate(self.clock.now())  # the old command acted until now
        self.target_q = np.array(q, dtype=np.float64)
        self.kp = np.array(kp, dtype=np.float64)
        self.kd = np.array(kd, dtype=np.float64)
        if self.keep_commands:
            self.commands.append({"q": self.target_q.copy(), "dq": np.array(dq, float), "kp": self.kp.copy(),
                                  "kd": self.kd.copy(), "tau": np.array(tau, float)})

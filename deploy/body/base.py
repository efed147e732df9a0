"""The body interface: read the latest low-level state, send a LowCmd-like PD command for every joint."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np


@dataclass
class BodyState:
    q: np.ndarray  # (N,) rad, Unitree motor order
    dq: np.ndarray  # (N,) rad/s
    imu_quat_wxyz: np.ndarray  # (4,) pelvis IMU orientation
    gyro: np.ndarray  # (3,) rad/s, pelvis frame
    stamp: float  # clock time when this state was measured/received
    tau_est: np.ndarray | None = None  # (N,) N m when the backend reports it
    # What a backend reports about the robot's health and identity (None: not reported, not checked).
    mode_machine: int | None = None  # robot type (deploy.embodiment.MODE_MACHINE), echoed in LowCmd
    tick: int | None = None  # the robot's LowState counter: must keep advancing
    motor_error: np.ndarray | None = None  # (N,) motorstate error bits per joint (0 = healthy)
    motor_temp_c: np.ndarray | None = None  # (N,) hottest temperature sensor of each motor, deg C
    remote_keys: int | None = None  # wireless remote buttons pressed (deploy.remote.BUTTONS bit map)
    remote_stamp: float | None = None  # clock time the remote last reported (None: no remote seen)
    other_commanders: int = 0  # rt/lowcmd publishers other than us (e.g. sport mode left on)

    def is_finite(self) -> bool:
        return bool(
            np.all(np.isfinite(self.q))
            and np.all(np.isfinite(self.dq))
            and np.all(np.isfinite(self.imu_quat_wxyz))
            and np.all(np.isfinite(self.gyro))
        )


class Body(ABC):
    """Joints are commanded as tau + kp * (q - q_meas) + kd * (dq - dq_meas), the Unitree motor law."""

    num_joints: int

    @abstractmethod
    def connect(self) -> None: ...

    @abstractmethod
    def close(self) -> None: ...

    @abstractmethod
    def read_state(self) -> BodyState | None:
        """The newest state (None until the first one arrives). Never blocks for long."""

    @abstractmethod
    def send(self, q: np.ndarray, dq: np.ndarray, kp: np.ndarray, kd: np.ndarray, tau: np.ndarray) -> None:
        """One command for all joints; arrays of length num_joints."""

    def _check_command(self, *arrays: np.ndarray) -> None:
        for a in arrays:
            if np.shape(a) != (self.num_joints,):
                raise ValueError(f"body command arrays must have shape ({self.num_joints},), got {np.shape(a)}")

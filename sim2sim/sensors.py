"""deploy's Body and PoseTracker interfaces over the simulated world, with the perturbations' noise and latency.

`MujocoBody` is the G1's low-level link: read_state() returns the joints, the pelvis IMU orientation and gyro at
the current simulation time (plus Gaussian noise), send() hands a LowCmd to the motor drivers (sim2sim.world,
which applies the actuator latency and the PD law). `MujocoTracker` is the motion-capture system: it samples the
pelvis and object poses at `rate_hz` and delivers each sample `latency_s` later, stamped with its capture time,
as deploy's UDP receiver does.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from deploy.body.base import Body, BodyState
from deploy.errors import BodyLinkError
from deploy.rotations import quat_wxyz_from_axis_angle, quat_wxyz_multiply
from deploy.tracking import Pose, PoseTracker, TrackedPoses, unseen_pose
from sim2sim.perturbations import Perturbation
from sim2sim.world import SimWorld


def rotate_randomly(quat_wxyz: np.ndarray, std_rad: float, rng: np.random.Generator) -> np.ndarray:
    """quat rotated by a random rotation vector with per-axis std `std_rad` (left-multiplied: world frame)."""
    if std_rad <= 0:
        return quat_wxyz
    rotvec = rng.normal(0.0, std_rad, 3)
    angle = float(np.linalg.norm(rotvec))
    if angle == 0.0:
        return quat_wxyz
    return quat_wxyz_multiply(quat_wxyz_from_axis_angle(rotvec / angle, angle), quat_wxyz)


class MujocoBody(Body):
    def __init__(self, world: SimWorld, num_joints: int, perturbation: Perturbation, rng: np.random.Generator):
        self.world = world
        self.num_joints = num_joints
        self.p = perturbation
        self.rng = rng
        self.connected = False
        self.reads = 0

    def connect(self) -> None:
        self.connected = True

    def close(self) -> None:
        self.connected = False

    def read_state(self) -> BodyState:
        if not self.connected:
            raise BodyLinkError("simulated body is not connected")
        q, dq, quat, gyro = self.world.body_state()
        p, rng = self.p, self.rng
        if p.joint_pos_noise > 0:
            q = q + rng.normal(0.0, p.joint_pos_noise, q.shape)
        if p.joint_vel_noise > 0:
            dq = dq + rng.normal(0.0, p.joint_vel_noise, dq.shape)
        if p.gyro_noise > 0:
            gyro = gyro + rng.normal(0.0, p.gyro_noise, 3)
        quat = rotate_randomly(quat, p.imu_rot_noise, rng)
        self.reads += 1
        return BodyState(q=q, dq=dq, imu_quat_wxyz=quat, gyro=gyro, stamp=self.world.t)

    def send(self, q, dq, kp, kd, tau) -> None:
        if not self.connected:
            raise BodyLinkError("simulated body is not connected")
        self._check_command(q, dq, kp, kd, tau)
        self.world.command(q, dq, kp, kd, tau)


class MujocoTracker(PoseTracker):
    def __init__(self, world: SimWorld, perturbation: Perturbation, rng: np.random.Generator,
                 rate_hz: float = 120.0):
        self.world = world
        self.latency_s = perturbation.tracker_latency_s
        self.pos_noise = perturbation.tracker_pos_noise
        self.rot_noise = perturbation.tracker_rot_noise
        self.rng = rng
        keep = int(np.ceil((self.latency_s + 0.5) * rate_hz)) + 2
        self._samples: deque[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = deque(maxlen=keep)
        world.add_listener(1.0 / rate_hz, self._sample)

    def _sample(self, t: float) -> None:
        self._samples.append((t, *self.world.pelvis_pose(), *self.world.object_pose()))

    def _noisy(self, pos: np.ndarray, quat: np.ndarray, stamp: float) -> Pose:
        if self.pos_noise > 0:
            pos = pos + self.rng.normal(0.0, self.pos_noise, 3)
        return Pose(pos, rotate_randomly(quat, self.rot_noise, self.rng), stamp)

    def read(self) -> TrackedPoses:
        delivered = self.world.t - self.latency_s + 1e-9
        for t, robot_pos, robot_quat, obj_pos, obj_quat in reversed(self._samples):
            if t <= delivered:
                return TrackedPoses(robot=self._noisy(robot_pos, robot_quat, t),
                                    object=self._noisy(obj_pos, obj_quat, t))
        return TrackedPoses(robot=unseen_pose(), object=unseen_pose())

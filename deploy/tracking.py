"""Pose tracking: world poses of the robot's pelvis and of the object, each with the time it was measured.

`PoseTracker.read()` returns the newest `TrackedPoses`; the runtime judges freshness from the stamps (a pose older
than two control periods stops the policy). Implementations here: `ReplayTracker` (plays the motion sidecar's
root and object trajectories against the clock) and `SimulatedTracker` (follows the reference frame the runtime
is tracking, with optional noise, latency and drop-outs). The UDP receiver for a real motion-capture system is in
deploy.tracking_udp.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass

import numpy as np

from deploy.clock import Clock, MonotonicClock
from deploy.motion import ReferenceMotion
from deploy.rotations import quat_wxyz_from_axis_angle, quat_wxyz_multiply

NEVER = float("-inf")
DEFAULT_PELVIS_POS = np.array([0.0, 0.0, 0.793])
DEFAULT_OBJECT_POS = np.array([0.45, 0.0, 0.75])
IDENTITY_WXYZ = np.array([1.0, 0.0, 0.0, 0.0])


@dataclass
class Pose:
    pos: np.ndarray  # (3,) m, world
    quat_wxyz: np.ndarray  # (4,)
    stamp: float = NEVER  # clock time of the measurement; NEVER if none has arrived

    def age(self, now: float) -> float:
        return now - self.stamp

    def is_finite(self) -> bool:
        return bool(np.all(np.isfinite(self.pos)) and np.all(np.isfinite(self.quat_wxyz)))


@dataclass
class TrackedPoses:
    robot: Pose
    object: Pose


def unseen_pose() -> Pose:
    return Pose(np.full(3, np.nan), np.full(4, np.nan), NEVER)


class PoseTracker(ABC):
    def connect(self) -> None:
        """Open sockets / start playback. Default: nothing to do."""
        return None

    def close(self) -> None:
        """Release resources. Default: nothing to do."""
        return None

    @abstractmethod
    def read(self) -> TrackedPoses:
        """The newest poses; never blocks."""

    def update_reference(self, frame: int) -> None:
        """The runtime reports which reference frame the policy now tracks. Real trackers ignore it."""
        return None


class NoTracker(PoseTracker):
    """For a policy that reads no tracked pose (contract.needs_tracker False): nothing is opened, nothing seen."""

    def read(self) -> TrackedPoses:
        return TrackedPoses(unseen_pose(), unseen_pose())


class ReplayTracker(PoseTracker):
    """Plays the motion's root and object trajectories in real time from connect(); holds the last frame."""

    def __init__(self, motion: ReferenceMotion, clock: Clock | None = None, loop: bool = False):
        self.motion = motion
        self.clock = clock or MonotonicClock()
        self.loop = loop
        self._t0: float | None = None

    def connect(self) -> None:
        self._t0 = self.clock.now()

    def frame_at(self, now: float) -> int:
        if self._t0 is None:
            self._t0 = now
        frame = int((now - self._t0) * self.motion.fps)
        return frame % self.motion.num_frames if self.loop else self.motion.frame_index(frame)

    def read(self) -> TrackedPoses:
        now = self.clock.now()
        f = self.frame_at(now)
        m = self.motion
        return TrackedPoses(
            robot=Pose(m.root_pos[f].copy(), m.root_quat_wxyz[f].copy(), now),
            object=Pose(m.object_pos[f].copy(), m.object_quat_wxyz[f].copy(), now),
        )


class SimulatedTracker(PoseTracker):
    """A mocap stand-in that sees the robot and object exactly where the tracked reference puts them.

    Before the policy starts, the reference frame is 0. `latency_s` delays what is seen (and its stamp);
    `pos_noise_std` (m) and `rot_noise_std` (rad) add Gaussian noise; `drop(which)` freezes one pose (tracking
    loss: its stamp stops advancing) until `restore(which)`. Without a motion the robot stands at the origin and
    the object rests in front of it.
    """

    def __init__(self, motion: ReferenceMotion | None, clock: Clock | None = None, latency_s: float = 0.0,
                 pos_noise_std: float = 0.0, rot_noise_std: float = 0.0, seed: int = 0):
        self.motion = motion
        self.clock = clock or MonotonicClock()
        self.latency_s = latency_s
        self.pos_noise_std = pos_noise_std
        self.rot_noise_std = rot_noise_std
        self.rng = np.random.default_rng(seed)
        self._history: deque[tuple[float, int]] = deque([(NEVER, 0)], maxlen=4096)
        self._dropped: dict[str, Pose] = {}

    def update_reference(self, frame: int) -> None:
        if frame != self._history[-1][1]:
            self._history.append((self.clock.now(), int(frame)))

    def _frame_seen_at(self, t: float) -> int:
        frame = self._history[0][1]
        for stamp, f in self._history:
            if stamp > t:
                break
            frame = f
        return frame

    def true_poses(self, frame: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if self.motion is None:
            return DEFAULT_PELVIS_POS.copy(), IDENTITY_WXYZ.copy(), DEFAULT_OBJECT_POS.copy(), IDENTITY_WXYZ.copy()
        f = self.motion.frame_index(frame)
        m = self.motion
        return m.root_pos[f].copy(), m.root_quat_wxyz[f].copy(), m.object_pos[f].copy(), m.object_quat_wxyz[f].copy()

    def true_robot_quat_wxyz(self) -> np.ndarray:
        """The pelvis orientation right now without noise or latency (feeds a simulated IMU)."""
        return self.true_poses(self._history[-1][1])[1]

    def _noisy(self, pos: np.ndarray, quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.pos_noise_std > 0:
            pos = pos + self.rng.normal(0.0, self.pos_noise_std, 3)
        if self.rot_noise_std > 0:
            rotvec = self.rng.normal(0.0, self.rot_noise_std, 3)
            angle = float(np.linalg.norm(rotvec))
            if angle > 0:
                quat = quat_wxyz_multiply(quat_wxyz_from_axis_angle(rotvec / angle, angle), quat)
        return pos, quat

    def drop(self, which: str) -> None:
        """Freeze 'robot' or 'object' at its last seen pose (the stamp stops advancing)."""
        self._dropped[which] = getattr(self.read(), which)

    def restore(self, which: str) -> None:
        self._dropped.pop(which, None)

    def read(self) -> TrackedPoses:
        seen_at = self.clock.now() - self.latency_s
        robot_pos, robot_quat, obj_pos, obj_quat = self.true_poses(self._frame_seen_at(seen_at))
        robot = Pose(*self._noisy(robot_pos, robot_quat), seen_at)
        obj = Pose(*self._noisy(obj_pos, obj_quat), seen_at)
        return TrackedPoses(robot=self._dropped.get("robot", robot), object=self._dropped.get("object", obj))

"""The evaluator inside an episode: watches the simulated world at every policy step, ends the episode.

It plugs into the unchanged runtime through two of deploy's own seams:
    - as the runtime's OperatorInput: each tick it records the robot's state (for videos), lowers the robot
      off the gantry once the runtime holds the default pose (HOLD), and asks for "stop" when the episode is
      over, so the runtime leaves POLICY through DAMP as it would on the robot;
    - around the ONNX policy (MonitoredPolicy): at policy tick t the world holds the state reached after t
      actions, which is compared with the reference frame of tick t (f(t) = t - warmup_frames, held at 0 during
      the policy's warmup, as the runtime's observation does); InterMimic's early-termination conditions (the
      thresholds the policy was trained with: its metadata's task, else configs/tasks/interaction.yaml) end the
      episode as they end a training episode.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial import cKDTree

from deploy.operator import OperatorInput
from deploy.safety import Phase
from robot_hoi import termination
from robot_hoi.termination import Thresholds
from sim2sim import metrics
from sim2sim.world import SimWorld


@dataclass
class ReferenceTrack:
    """Per-frame reference quantities one episode compares against (frames of the policy's motion)."""

    link_pos: np.ndarray  # (T, L, 3)
    object_points: np.ndarray  # (T, P, 3) world surface samples of the reference object
    d_hat: np.ndarray  # (T, L, 3) reference link -> nearest object surface point
    hand_contact: np.ndarray | None  # (T, 2) bool, hands that must touch the object; None: not known
    points_local: np.ndarray  # (P, 3)

    @classmethod
    def build(cls, motion, points_local: np.ndarray, hand_contact: np.ndarray | None) -> ReferenceTrack:
        points_world = metrics.object_points_world(points_local, motion.object_pos, motion.object_quat_wxyz)
        d_hat = metrics.nearest_surface_vectors(motion.link_pos, points_world)
        return cls(motion.link_pos, points_world, d_hat, hand_contact, points_local)


class EpisodeMonitor(OperatorInput):
    def __init__(self, world: SimWorld, ref: ReferenceTrack, thresholds: Thresholds, last_frame: int,
                 keep_qpos: bool = True, warmup_frames: int = 0):
        self.world = world
        self.ref = ref
        self.thresholds = thresholds
        self.last_frame = int(last_frame)
        self.warmup_frames = int(warmup_frames)
        self.keep_qpos = keep_qpos
        self.runtime = None
        self._tree = cKDTree(ref.points_local)
        self._hand_links = termination.hand_link_groups(world.layout.links.names)
        # per policy tick t >= 1 (frames that count): what the metrics need
        self.ticks: list[int] = []
        self.frames: list[int] = []
        self.link_pos: list[np.ndarray] = []
        self.link_error: list[float] = []
        self.object_error: list[float] = []
        self.interaction_error: list[float] = []
        self.qpos_trace: list[np.ndarray] = []
        self.time_trace: list[float] = []
        self.phase_trace: list[int] = []
        self.policy_started_at: float | None = None
        self.saturation_at_start = self.saturation_now = (0, 0)  # (saturated PD updates, PD updates)
        self.contact_loss = np.zeros(2, dtype=int)
        self.terminations: list[str] = []
        self.reached_end = False
        self.finished = False
        self._stop_sent = False

    def attach(self, runtime) -> None:
        self.runtime = runtime

    # ------------------------------------------------------------------ OperatorInput
    def poll(self) -> list[str]:
        world = self.world
        phase = self.runtime.phase if self.runtime is not None else Phase.WAIT_STATE
        if self.keep_qpos:
            self.time_trace.append(world.t)
            self.phase_trace.append(int(phase))
            self.qpos_trace.append(world.data.qpos.copy())
        if world.gantry_on and phase in (Phase.HOLD, Phase.POLICY):
            world.release_gantry()
        if self.finished and not self._stop_sent:
            self._stop_sent = True
            return ["stop"]
        return []

    # ------------------------------------------------------------------ one policy step
    def on_policy_step(self, tick: int) -> None:
        if self.finished:
            return
        world = self.world
        if self.policy_started_at is None:
            self.policy_started_at = world.t
            self.saturation_at_start = (world.torque_saturated_updates, world.pd_ticks)
        self.saturation_now = (world.torque_saturated_updates, world.pd_ticks)
        if tick < 1:
            return
        mujoco.mj_kinematics(world.model, world.data)  # link frames of the current qpos (mj_step left older ones)
        f = self.frame_of(tick)
        links = world.link_positions()
        obj_pos, rot = world.object_frame()
        points = self.ref.points_local @ rot.T + obj_pos
        # nearest surface sample of each link, found in the object frame (a KD-tree built once per episode)
        _, nearest = self._tree.query((links - obj_pos) @ rot)
        d = points[nearest] - links
        link_err = float(metrics.mean_position_error(links[None], self.ref.link_pos[f][None])[0])
        obj_err = float(np.linalg.norm(points - self.ref.object_points[f], axis=-1).mean())
        inter_err = float(metrics.interaction_distance_error(d, self.ref.d_hat[f]))
        self.ticks.append(tick)
        self.frames.append(f)
        self.link_pos.append(links)
        self.link_error.append(link_err)
        self.object_error.append(obj_err)
        self.interaction_error.append(inter_err)

        th = self.thresholds
        if self.ref.hand_contact is not None and tick > self.warmup_frames:  # training: not during warmup
            distance, ref_distance = np.linalg.norm(d, axis=-1), np.linalg.norm(self.ref.d_hat[f], axis=-1)
            nearest = np.array([distance[ids].min() for ids in self._hand_links])
            ref_nearest = np.array([ref_distance[ids].min() for ids in self._hand_links])
            self.contact_loss = termination.contact_loss_count(
                self.contact_loss, self.ref.hand_contact[f], world.hand_contact(), nearest, th, ref_nearest)
        ended = termination.ended(th, termination.Measured(np.float64(link_err), world.data.qpos[2],
                                                           np.float64(obj_err), np.float64(inter_err),
                                                           self.contact_loss))
        reasons = [name for name, hit in ended.items() if hit]
        if reasons:
            self.terminations = reasons
            self.finished = True
        elif f >= self.last_frame:
            self.reached_end = True
            self.finished = True

    def frame_of(self, tick: int) -> int:
        """Reference frame of policy tick t (deploy.contract: the clock holds frame 0 during the warmup)."""
        return min(max(int(tick) - self.warmup_frames, 0), len(self.ref.link_pos) - 1)


    def policy_torque_saturation(self) -> float | None:
        """Share of the PD updates while the policy ran in which some motor hit its effort limit."""
        updates = self.saturation_now[1] - self.saturation_at_start[1]
        return (self.saturation_now[0] - self.saturation_at_start[0]) / updates if updates > 0 else None


class MonitoredPolicy:
    """The ONNX policy as the runtime calls it, telling the monitor which policy tick is being computed."""

    def __init__(self, policy, monitor: EpisodeMonitor):
        self.policy = policy
        self.monitor = monitor

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.monitor.on_policy_step(self.monitor.runtime.policy_tick)
        return self.policy(obs)

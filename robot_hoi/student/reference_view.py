"""A teacher's view of the student environment: the simulated state of the env, the teacher's own reference.

With reference distillation the student env tracks the teachers' rollouts, but each teacher was trained to read
its observation (InterMimic Eq. 1) against its MoCap reference and to output joint targets around that reference.
`ReferenceTimeline` holds those references; `ReferenceView` presents the env's state with them, so the unchanged
observation terms (tasks/interaction/mdp/observations.py) compute exactly what the teacher saw in training.
Frame f of a student clip is frame f of the teacher's clip (distilled references keep the clip's frame numbering).
"""

from __future__ import annotations

from types import SimpleNamespace

import torch
from torch import Tensor

from robot_hoi.tasks.interaction.env import ReferenceFrame
from robot_hoi.tasks.interaction.mdp import observations as obs_terms
from robot_hoi.tasks.interaction.reference import ReferenceMotion

WRIST_LINKS = ("left_wrist_yaw_link", "right_wrist_yaw_link")


class ReferenceTimeline:
    """Reference motions concatenated as the env does (clip c covers frames start[c] .. end[c])."""

    def __init__(self, references: list[ReferenceMotion], link_names: list[str]) -> None:
        cat = lambda name: torch.cat([getattr(r, name) for r in references])  # noqa: E731
        self.link_pos, self.link_quat = cat("link_pos"), cat("link_quat_wxyz")
        self.d_hat, self.hand_contact = cat("d_hat"), cat("hand_contact")
        self.object_pos, self.object_quat = cat("object_pos"), cat("object_quat_wxyz")
        self.robot_qpos, self.joint_pos = cat("robot_qpos"), cat("joint_pos")
        lengths = torch.tensor([r.num_frames for r in references])
        self.start = torch.cumsum(lengths, 0) - lengths
        self.end = self.start + lengths - 1
        wrists = [link_names.index(n) for n in WRIST_LINKS]
        self.hand_distance = self.d_hat[:, wrists].norm(dim=-1)

    def frame(self, idx: Tensor) -> ReferenceFrame:
        return ReferenceFrame(
            link_pos=self.link_pos[idx], link_quat_wxyz=self.link_quat[idx], d_hat=self.d_hat[idx],
            object_pos=self.object_pos[idx], object_quat_wxyz=self.object_quat[idx],
            hand_contact=self.hand_contact[idx], hand_distance=self.hand_distance[idx],
            root_pos=self.robot_qpos[idx, 0:3], root_quat_wxyz=self.robot_qpos[idx, 3:7],
            joint_pos=self.joint_pos[idx],
        )


class ReferenceView:
    """Duck-types the env for observation terms: state attributes come from `env`, references from `timeline`."""

    def __init__(self, env, timeline: ReferenceTimeline, keyframes, warmup_frames: int) -> None:
        self._env = env
        self._timeline = timeline
        self.cfg = SimpleNamespace(keyframes=tuple(keyframes), warmup_frames=int(warmup_frames))

    def __getattr__(self, name: str):
        return getattr(self._env, name)

    def index(self, env_index: Tensor | None = None) -> Tensor:
        """The env's reference frame mapped onto the timeline (same offset into the same clip)."""
        env = self._env
        env_index = env.ref_index if env_index is None else env_index
        offset = env_index - env.clip_start[env.clip_id]
        start, end = self._timeline.start[env.clip_id], self._timeline.end[env.clip_id]
        return torch.minimum(start + offset.clamp(min=0), end)

    def reference_at(self, k: int) -> ReferenceFrame:
        idx = self.index()
        if k:
            idx = torch.minimum(idx + k, self._timeline.end[self._env.clip_id])
        return self._timeline.frame(idx)

    def action_offset(self, mode: str) -> Tensor:
        """The PD target of a zero action for a policy trained with env.action_offset `mode` on this timeline:
        the default pose, or the reference joints of the frame the next step moves to (as the env computes it)."""
        env = self._env
        if mode == "default":
            return env.default_joint_pos.expand(env.num_envs, -1)
        next_index = torch.where(env.warmup_left > 0, env.ref_index,
                                 torch.minimum(env.ref_index + 1, env.clip_end[env.clip_id]))
        return self._timeline.joint_pos[self.index(next_index)]

    def teacher_observation(self) -> Tensor:
        return obs_terms.teacher_observation(self)

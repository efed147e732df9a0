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

from robot_hoi.tasks.interaction.env import InteractionEnv, ReferenceFrame
from robot_hoi.tasks.interaction.mdp import observations as obs_terms
from robot_hoi.tasks.interaction.reference import ReferenceMotion


class ReferenceTimeline:
    """Reference motions laid out exactly as InteractionEnv lays out its own (its _setup_references: the same
    ref_* tensors, clip c covering frames clip_start[c] .. clip_end[c]), so the env's reference_at reads them."""

    def __init__(self, references: list[ReferenceMotion], env) -> None:
        holder = SimpleNamespace(cfg=env.cfg, layout=env.layout, device=env.device)
        InteractionEnv._setup_references(holder, references)
        self.tensors = vars(holder)

    @property
    def start(self) -> Tensor:
        return self.tensors["clip_start"]

    @property
    def end(self) -> Tensor:
        return self.tensors["clip_end"]

    @property
    def joint_pos(self) -> Tensor:
        return self.tensors["ref_joint_pos"]

    def frame(self, idx: Tensor, end: Tensor) -> ReferenceFrame:
        """The env's ReferenceFrame at timeline frames `idx` (InteractionEnv.reference_at on this timeline)."""
        clock = SimpleNamespace(**self.tensors, ref_index=idx, _clip_end=lambda: end)
        return InteractionEnv.reference_at(clock, 0)


class ReferenceView:
    """Duck-types the env for observation terms: state attributes come from `env`, references from `timeline`."""

    def __init__(self, env, timeline: ReferenceTimeline, keyframes, warmup_frames: int,
                 teacher_obs: str | None = None, offset_mode: str | None = None) -> None:
        self._env = env
        self._timeline = timeline
        self.cfg = SimpleNamespace(keyframes=tuple(keyframes), warmup_frames=int(warmup_frames),
                                   teacher_obs=teacher_obs or env.cfg.teacher_obs)  # default: as the env's
        self.offset_mode = offset_mode or env.cfg.action_offset  # the teachers' env.action_offset

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
        end = self._timeline.end[self._env.clip_id]
        return self._timeline.frame(torch.minimum(self.index() + k, end), end)

    def action_offset(self, mode: str) -> Tensor:
        """The PD target of a zero action for a policy trained with env.action_offset `mode` on this timeline, as
        the env computes its own: the default pose, or the reference joints of the frame the next step moves to
        (glided in from the start pose during the warmup)."""
        frame, steps_done = self._env.offset_frame()
        return self._zero_action_target(mode, self._timeline.joint_pos, self.index(frame), steps_done)

    @property
    def last_actions(self) -> Tensor:
        """The env's last action re-expressed around this timeline: the action that sends the same PD targets, which
        is what a teacher's `last_action` term read in its own env (zero after a reset, as there). Read straight
        from the env, a teacher on a distilled reference sees its own last action shifted by (distilled - MoCap
        joints) / scale every step, and falls where it would not (docs/experiments/student.md)."""
        env = self._env
        frame, steps_done = env.offset_frame(previous=True)
        own = self._zero_action_target(env.cfg.action_offset, env.ref_joint_pos, frame, steps_done)
        theirs = self._zero_action_target(self.offset_mode, self._timeline.joint_pos, self.index(frame), steps_done)
        clip = env.cfg.action_clip
        moved = (env.last_actions + (own - theirs) / env.action_scale).clamp(-clip, clip)
        return torch.where((env.episode_length > 0)[:, None], moved, torch.zeros_like(moved))

    def _zero_action_target(self, mode: str, joint_table: Tensor, frame: Tensor, steps_done: Tensor) -> Tensor:
        env = self._env
        if mode == "default":
            return env.default_joint_pos.expand(env.num_envs, -1)
        return env.zero_action_target(joint_table[frame], steps_done)

    def teacher_observation(self) -> Tensor:
        return obs_terms.teacher_observation(self)

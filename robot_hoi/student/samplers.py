"""The env's start sampler (InteractionEnv.start_sampler): which clip each reset env starts on, and for
non-stand starts the state transition field's start (SkillMimic-V2). Keeps per-env records of how the current
episode started (for ATS) and the masked frames left (read by student_env.StudentEnv)."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from robot_hoi.tasks.interaction.env import StartPlan


class StartSampler:
    def __init__(self, num_envs: int, num_clips: int, generator: torch.Generator,
                 clip_probabilities: Callable[[], Tensor] | None = None, field=None) -> None:
        """clip_probabilities: () -> (num_clips,) (None: uniform); field: a stf.StateTransitionField for the
        non-stand starts (None: the env's own reference/PSI starts)."""
        self.num_clips = num_clips
        self.generator = generator
        self.clip_probabilities = clip_probabilities
        self.field = field
        self.masked_left = torch.zeros(num_envs, dtype=torch.long) if field is not None else None
        self.records = {"custom": torch.zeros(num_envs, dtype=torch.bool),
                        "centroid": torch.full((num_envs,), -1, dtype=torch.long),
                        "start_frame": torch.zeros(num_envs, dtype=torch.long),
                        "hold": torch.zeros(num_envs, dtype=torch.long)}

    def probabilities(self) -> Tensor:
        if self.clip_probabilities is None:
            return torch.full((self.num_clips,), 1.0 / self.num_clips)
        return self.clip_probabilities()

    def plan(self, env, env_ids: Tensor) -> StartPlan:
        """Drawn on the host (the samplers' tables are CPU tensors), handed to the env on its device."""
        env_ids = env_ids.cpu()
        n = env_ids.numel()
        clip = torch.multinomial(self.probabilities(), n, replacement=True, generator=self.generator)
        custom = torch.zeros(n, dtype=torch.bool)
        state = frame = hold = None
        centroid = torch.full((n,), -1, dtype=torch.long)
        if self.field is not None:
            custom = torch.rand(n, generator=self.generator) >= env.cfg.init.stand_start_probability
            rows = custom.nonzero().flatten()
            if rows.numel():
                starts = self.field.sample(clip[rows])
                state = torch.zeros(n, starts.state.shape[1])
                frame, hold = torch.zeros(n, dtype=torch.long), torch.zeros(n, dtype=torch.long)
                state[rows], frame[rows], hold[rows], centroid[rows] = \
                    starts.state, starts.frame, starts.hold, starts.centroid
            else:
                custom = torch.zeros(n, dtype=torch.bool)
        self.records["custom"][env_ids] = custom
        self.records["centroid"][env_ids] = centroid
        self.records["start_frame"][env_ids] = frame if frame is not None else 0
        self.records["hold"][env_ids] = hold if hold is not None else 0
        if self.masked_left is not None:
            self.masked_left[env_ids] = hold if hold is not None else 0
        on_env = lambda t: None if t is None else t.to(env.device)  # noqa: E731
        return StartPlan(clip=on_env(clip), custom=on_env(custom), state=on_env(state), frame=on_env(frame),
                         hold=on_env(hold))

    def state_dict(self) -> dict:
        return {"generator": self.generator.get_state()}

    def load_state_dict(self, state: dict) -> None:
        self.generator.set_state(state["generator"])

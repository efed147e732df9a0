"""ComplexMimic's difficulty-aware sampling wired into the student run (Stage II; the experts and the routing
of Stage I are in experts.py): reset clips drawn from the sampler's p(m), difficulties updated every K
iterations from the episodes that ended."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from robot_hoi.student.config import ComplexMimicConfig
from robot_hoi.student.difficulty import DifficultyAwareSampler
from robot_hoi.student.samplers import StartSampler


class DifficultySetup:
    def __init__(self, cfg: ComplexMimicConfig, group_of: list[int], seed: int = 0,
                 reduce: Callable[[Tensor], Tensor] | None = None) -> None:
        """reduce: sums over data-parallel ranks (None: one process)."""
        self.cfg = cfg
        self.reduce = reduce
        self.sampler = DifficultyAwareSampler(group_of, cfg)
        self.generator = torch.Generator().manual_seed(seed + 104729)

    def attach(self, runner, student_env) -> None:
        env = student_env.env
        das = self.sampler
        if env.start_sampler is None:
            env.start_sampler = StartSampler(env.num_envs, len(env.references), self.generator, das.probabilities)
            runner.stateful["start_sampler"] = env.start_sampler
        else:  # SkillMimic-V2's sampler already places the starts: DAS picks their clips
            env.start_sampler.clip_probabilities = das.probabilities
        student_env.listeners.append(das.observe)
        runner.stateful["difficulty"] = das
        every = self.cfg.update_every

        def update(iteration: int) -> dict[str, float] | None:
            return das.update(self.reduce) if iteration > 0 and iteration % every == 0 else None

        runner.iteration_hooks.append(update)

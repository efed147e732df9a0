"""A tiny CPU environment that follows the VecEnv contract, for tests, benchmarks and smoke runs.

ReachEnv: a point in [-1, 1]^d must move to a per-episode target. Action = velocity command (clipped to
[-1, 1]), reward = 1 - distance to the target each step. Leaving the arena (|x| > 1.5) terminates; episodes
time out after max_episode_length. The optimal policy moves straight to the target, so returns have a clear
ceiling (about max_episode_length) and a random policy scores far below it.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor


class ReachEnv:
    def __init__(
        self,
        num_envs: int = 64,
        dim: int = 2,
        max_episode_length: int = 32,
        step_size: float = 0.2,
        device: str | torch.device = "cpu",
        seed: int = 0,
    ) -> None:
        self.num_envs = num_envs
        self.num_actions = dim
        self.device = torch.device(device)
        self.max_episode_length = max_episode_length
        self.step_size = step_size
        # "critic" adds privileged information (time left) the actor does not get.
        self.obs_dims = {"policy": 2 * dim, "critic": 2 * dim + 1}
        self._gen = torch.Generator(device=self.device).manual_seed(seed)
        self.pos = torch.zeros(num_envs, dim, device=self.device)
        self.target = torch.zeros(num_envs, dim, device=self.device)
        self.steps = torch.zeros(num_envs, dtype=torch.long, device=self.device)

    def _uniform(self, n: int, low: float, high: float) -> Tensor:
        r = torch.rand(n, self.num_actions, generator=self._gen, device=self.device)
        return low + (high - low) * r

    def _reset_envs(self, ids: Tensor) -> None:
        n = int(ids.numel())
        if n:
            self.pos[ids] = self._uniform(n, -1.0, 1.0)
            self.target[ids] = self._uniform(n, -1.0, 1.0)
            self.steps[ids] = 0

    def _obs(self) -> dict[str, Tensor]:
        policy = torch.cat([self.pos, self.target - self.pos], dim=-1)
        time_left = (1.0 - self.steps.float() / self.max_episode_length).unsqueeze(-1)
        return {"policy": policy, "critic": torch.cat([policy, time_left], dim=-1)}

    def reset(self) -> dict[str, Tensor]:
        self._reset_envs(torch.arange(self.num_envs, device=self.device))
        return self._obs()

    def step(self, actions: Tensor) -> tuple[dict[str, Tensor], Tensor, Tensor, Tensor, dict[str, Any]]:
        actions = torch.clamp(actions.to(self.device), -1.0, 1.0)
        self.pos = self.pos + self.step_size * actions
        self.steps += 1
        distance = torch.linalg.vector_norm(self.pos - self.target, dim=-1)
        reward = 1.0 - distance
        terminated = (self.pos.abs() > 1.5).any(dim=-1)
        truncated = (self.steps >= self.max_episode_length) & ~terminated
        extras: dict[str, Any] = {
            "log": {
                "Episode_Reward/progress": float(reward.mean()),
                "Metrics/within_0.1": float((distance < 0.1).float().mean()),
            },
            "final_obs": self._obs(),
        }
        done = terminated | truncated
        if bool(done.any()):
            extras["episode_done"] = {"final_distance": distance[done]}
            self._reset_envs(done.nonzero().squeeze(-1))
        return self._obs(), reward, terminated, truncated, extras

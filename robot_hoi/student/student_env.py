"""The student's VecEnv: an InteractionEnv plus what the options need, without changing the task itself.

- masked frames (SkillMimic-V2 Sec. 4.3): while the start sampler's `masked_left` counts down for an env, its
  reward is excluded (0): the reference clock is held there, the state is only bridging to the reference;
- per-episode records for the samplers (clip, success, return without masked frames, length, and what the start
  sampler recorded at the episode's start) sent to `listeners`;
- extra observation groups (e.g. the SkillMimic-V2 history embedding), providers called every step.
Everything else is delegated to the wrapped env (attributes included), so teachers and samplers see the env.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import torch
from torch import Tensor


@dataclass
class EpisodeBatch:
    """Episodes that ended in one step (k rows)."""

    clip: Tensor  # (k,) long
    success: Tensor  # (k,) float 0/1
    ret: Tensor  # (k,) undiscounted return, masked frames excluded
    length: Tensor  # (k,) steps
    start: dict[str, Tensor] = field(default_factory=dict)  # start sampler records (k,) each


class ObservationProvider(Protocol):
    dim: int

    def __call__(self, env, obs: dict[str, Tensor], reset: Tensor) -> Tensor:
        """(N, dim) for the current step; `reset` (N,) bool marks envs whose episode just started."""
        ...


def fresh_providers(providers: dict[str, ObservationProvider], num_envs: int) -> dict[str, ObservationProvider]:
    """Providers for another env: stateful ones (with `fresh`) get their own buffers, stateless ones are shared."""
    return {name: p.fresh(num_envs) if hasattr(p, "fresh") else p for name, p in providers.items()}


class StudentEnv:
    def __init__(self, env, providers: dict[str, ObservationProvider] | None = None) -> None:
        self.env = env
        self.providers = dict(providers or {})
        self.listeners: list[Callable[[EpisodeBatch], None]] = []
        self.num_envs, self.num_actions = env.num_envs, env.num_actions
        self.device, self.max_episode_length = env.device, env.max_episode_length
        self.obs_dims = {**env.obs_dims, **{name: int(p.dim) for name, p in self.providers.items()}}
        self._returns = torch.zeros(env.num_envs, device=env.device)
        self._lengths = torch.zeros(env.num_envs, dtype=torch.long, device=env.device)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.env, name)

    def _augment(self, obs: dict[str, Tensor], reset: Tensor) -> dict[str, Tensor]:
        for name, provider in self.providers.items():
            obs[name] = provider(self.env, obs, reset)
        return obs

    def reset(self) -> dict[str, Tensor]:
        obs = self.env.reset()
        self._returns.zero_()
        self._lengths.zero_()
        return self._augment(obs, torch.ones(self.num_envs, dtype=torch.bool, device=self.device))

    def step(self, actions: Tensor):
        """The env's step with the options' bookkeeping on the env's device; only listeners (host-side samplers)
        read episodes back, as CPU tensors."""
        sampler = self.env.start_sampler
        masked = None
        if sampler is not None and getattr(sampler, "masked_left", None) is not None:
            masked = (sampler.masked_left > 0).to(self.device)
            sampler.masked_left.sub_(1).clamp_(min=0)  # before the step: resets inside it write fresh counts
        records = {k: v.clone() for k, v in getattr(sampler, "records", {}).items()} if self.listeners else {}
        obs, reward, terminated, truncated, extras = self.env.step(actions)
        if masked is not None:
            reward = torch.where(masked, torch.zeros_like(reward), reward)
            extras.setdefault("log", {})["Metrics/masked_fraction"] = masked.float().mean()
        self._returns += reward
        self._lengths += 1
        done = terminated | truncated
        if self.listeners and bool(done.any()):
            host_done = done.cpu()
            batch = EpisodeBatch(
                clip=extras["episode"]["clip_id"].long().cpu(), success=extras["episode"]["success"].cpu(),
                ret=self._returns[done].cpu(), length=self._lengths[done].cpu(),
                start={k: v[host_done] for k, v in records.items()})
            for listener in self.listeners:
                listener(batch)
        self._returns.masked_fill_(done, 0.0)
        self._lengths.masked_fill_(done, 0)
        return self._augment(obs, done), reward, terminated, truncated, extras

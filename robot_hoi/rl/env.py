"""The contract between an environment and the RL code (PPO, distillation, evaluation).

Any batched environment with these attributes and methods works; nothing needs to inherit from VecEnv.

Shapes (N = num_envs), all tensors on `env.device`:
- observations are a dict of named groups, each (N, obs_dims[name]) float32. Usual names: "policy" (what the
  deployed actor sees), "critic" (privileged), "teacher"/"student" for distillation. The runner concatenates the
  groups listed in its config for the actor and for the critic.
- reward (N,) float32; terminated (N,) bool (failure or success: no bootstrap); truncated (N,) bool (time-out
  at max_episode_length: the value of the state reached is bootstrapped).
- Environments reset finished envs themselves, so `step` returns the first observation of the new episode for
  those rows.

extras (a dict) may hold:
- "log": {name: float | 0-d tensor} scalars to log for this step, e.g. "Episode_Reward/<term>",
  "Metrics/success". The runner averages each over the iteration and writes it under the same name.
- "final_obs": {group: (N, dim) tensor} observations of the state reached *before* the auto-reset; rows are only
  read where truncated. Used to bootstrap time-outs exactly; without it V(state before the step) stands in.
- "episode_done": {name: tensor (k,) or float} statistics of episodes that ended this step, averaged over the
  iteration and logged as "Episode/<name>".
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import torch
from torch import Tensor

from robot_hoi.errors import UserError


@runtime_checkable
class VecEnv(Protocol):
    num_envs: int
    num_actions: int
    device: torch.device
    obs_dims: dict[str, int]
    max_episode_length: int

    def reset(self) -> dict[str, Tensor]:
        """Reset every env; returns the observation groups."""
        ...

    def step(self, actions: Tensor) -> tuple[dict[str, Tensor], Tensor, Tensor, Tensor, dict[str, Any]]:
        """Apply actions (N, num_actions); returns (obs, reward, terminated, truncated, extras)."""
        ...


def concat_groups(obs: dict[str, Tensor], groups: list[str]) -> Tensor:
    """Concatenate named observation groups along the feature axis, in the given order."""
    return obs[groups[0]] if len(groups) == 1 else torch.cat([obs[g] for g in groups], dim=-1)


def group_dim(env: VecEnv, groups: list[str], role: str) -> int:
    """Total width of `groups`, raising a UserError that lists what the env offers when one is missing."""
    missing = [g for g in groups if g not in env.obs_dims]
    if missing:
        raise UserError(
            f"{role} observation group(s) {missing} not provided by {type(env).__name__}; "
            f"it offers {sorted(env.obs_dims)} (set runner.{role}_obs_groups in the training config)"
        )
    return sum(int(env.obs_dims[g]) for g in groups)

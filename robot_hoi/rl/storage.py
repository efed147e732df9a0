"""Rollout storage (horizon x num_envs), GAE(lambda) returns and the minibatch generator.

Time-outs are not handled here: the caller folds gamma * V(final state) into the reward of a truncated step
and marks it done, so GAE only needs one `dones` flag that cuts the bootstrap chain.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import torch
from torch import Tensor


def compute_gae(
    rewards: Tensor, values: Tensor, dones: Tensor, last_values: Tensor, gamma: float, lam: float
) -> tuple[Tensor, Tensor]:
    """Generalised advantage estimation over a (T, N) rollout.

    dones[t] = 1 means the episode ended at step t, so values from step t+1 (the next episode) are not used.
    last_values (N,) is V of the observation after the final step. Returns (advantages, returns), both (T, N).
    """
    horizon = rewards.shape[0]
    advantages = torch.zeros_like(rewards)
    running = torch.zeros_like(last_values)
    for t in reversed(range(horizon)):
        next_values = last_values if t == horizon - 1 else values[t + 1]
        not_done = 1.0 - dones[t].float()
        delta = rewards[t] + gamma * not_done * next_values - values[t]
        running = delta + gamma * lam * not_done * running
        advantages[t] = running
    return advantages, advantages + values


@dataclass
class Minibatch:
    actor_input: Tensor  # normalised, as the actor saw it during the rollout
    critic_input: Tensor
    extra_obs: dict[str, Tensor]  # raw groups kept for an extra actor loss
    actions: Tensor
    old_log_probs: Tensor
    old_mean: Tensor
    old_std: Tensor
    old_values: Tensor
    advantages: Tensor
    returns: Tensor


class RolloutStorage:
    def __init__(
        self,
        horizon: int,
        num_envs: int,
        actor_dim: int,
        critic_dim: int,
        num_actions: int,
        extra_obs_dims: dict[str, int] | None = None,
        device: torch.device | str = "cpu",
    ) -> None:
        self.horizon = horizon
        self.num_envs = num_envs
        self.device = torch.device(device)

        def buf(*shape: int) -> Tensor:
            return torch.zeros(horizon, num_envs, *shape, device=self.device)

        self.actor_inputs = buf(actor_dim)
        self.critic_inputs = buf(critic_dim)
        self.extra_obs = {name: buf(dim) for name, dim in (extra_obs_dims or {}).items()}
        self.actions = buf(num_actions)
        self.action_means = buf(num_actions)
        self.action_stds = buf(num_actions)
        self.log_probs = buf()
        self.values = buf()
        self.rewards = buf()
        self.dones = buf()
        self.advantages = buf()
        self.returns = buf()
        self.step = 0

    @property
    def batch_size(self) -> int:
        return self.horizon * self.num_envs

    @property
    def full(self) -> bool:
        return self.step == self.horizon

    def add(
        self,
        *,
        actor_input: Tensor,
        critic_input: Tensor,
        actions: Tensor,
        log_probs: Tensor,
        action_mean: Tensor,
        action_std: Tensor,
        values: Tensor,
        rewards: Tensor,
        dones: Tensor,
        extra_obs: dict[str, Tensor] | None = None,
    ) -> None:
        if self.full:
            raise RuntimeError("rollout storage is full; call clear() after the update")
        t = self.step
        self.actor_inputs[t].copy_(actor_input)
        self.critic_inputs[t].copy_(critic_input)
        for name, buffer in self.extra_obs.items():
            buffer[t].copy_((extra_obs or {})[name])
        self.actions[t].copy_(actions)
        self.log_probs[t].copy_(log_probs)
        self.action_means[t].copy_(action_mean)
        self.action_stds[t].copy_(action_std.expand_as(action_mean))
        self.values[t].copy_(values)
        self.rewards[t].copy_(rewards)
        self.dones[t].copy_(dones.float())
        self.step += 1

    def clear(self) -> None:
        self.step = 0

    def compute_returns(self, last_values: Tensor, gamma: float, lam: float) -> None:
        if not self.full:
            raise RuntimeError(f"rollout has {self.step} of {self.horizon} steps; cannot compute returns yet")
        self.advantages, self.returns = compute_gae(
            self.rewards, self.values, self.dones, last_values, gamma, lam
        )

    def minibatches(
        self, num_minibatches: int, num_epochs: int, normalize_advantage: bool = True
    ) -> Iterator[Minibatch]:
        """Shuffled minibatches: num_epochs passes, each split into num_minibatches equal parts.

        When batch_size is not a multiple of num_minibatches the remainder is left out of that epoch (a different
        random remainder each epoch).
        """
        batch = self.batch_size
        size = batch // num_minibatches
        if size == 0:
            raise ValueError(f"{num_minibatches} minibatches from a rollout of only {batch} samples")
        advantages = self.advantages.reshape(-1)
        if normalize_advantage:
            advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
        flat = {
            "actor_input": self.actor_inputs.reshape(batch, -1),
            "critic_input": self.critic_inputs.reshape(batch, -1),
            "actions": self.actions.reshape(batch, -1),
            "old_log_probs": self.log_probs.reshape(-1),
            "old_mean": self.action_means.reshape(batch, -1),
            "old_std": self.action_stds.reshape(batch, -1),
            "old_values": self.values.reshape(-1),
            "advantages": advantages,
            "returns": self.returns.reshape(-1),
        }
        extra = {name: buffer.reshape(batch, -1) for name, buffer in self.extra_obs.items()}
        for _ in range(num_epochs):
            order = torch.randperm(batch, device=self.device)
            for i in range(num_minibatches):
                idx = order[i * size : (i + 1) * size]
                yield Minibatch(
                    **{key: value[idx] for key, value in flat.items()},
                    extra_obs={name: value[idx] for name, value in extra.items()},
                )

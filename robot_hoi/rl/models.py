"""Actor-critic MLPs: a Gaussian actor with a state-independent std and a value critic, each with its own
input normaliser. Teacher policies in InterMimic are ReLU MLPs [1024, 1024, 512], critics the same.

Observations passed to `act`, `act_inference` and `evaluate` are raw (un-normalised) tensors; the PPO update works
on already-normalised inputs through `distribution_normalized` / `value_normalized`, because the rollout stores the
exact inputs the networks saw.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn
from torch.distributions import Normal

from robot_hoi.rl.config import ActorCriticConfig
from robot_hoi.rl.normalizer import RunningNormalizer

_ACTIVATIONS = {"relu": nn.ReLU, "elu": nn.ELU, "tanh": nn.Tanh}


def build_mlp(
    in_dim: int, hidden_dims: list[int], out_dim: int, activation: str, out_gain: float
) -> nn.Sequential:
    """MLP with orthogonal weights (gain sqrt(2) on hidden layers, `out_gain` on the output) and zero biases."""
    layers: list[nn.Module] = []
    dims = [in_dim, *hidden_dims]
    for a, b in zip(dims[:-1], dims[1:], strict=True):
        linear = nn.Linear(a, b)
        nn.init.orthogonal_(linear.weight, gain=math.sqrt(2.0))
        nn.init.zeros_(linear.bias)
        layers += [linear, _ACTIVATIONS[activation]()]
    head = nn.Linear(dims[-1], out_dim)
    nn.init.orthogonal_(head.weight, gain=out_gain)
    nn.init.zeros_(head.bias)
    layers.append(head)
    return nn.Sequential(*layers)


class ExportedPolicy(nn.Module):
    """Raw observation -> action mean (normaliser baked in). What ONNX export traces."""

    def __init__(self, normalizer: nn.Module, actor: nn.Module) -> None:
        super().__init__()
        self.normalizer = normalizer
        self.actor = actor

    def forward(self, obs: Tensor) -> Tensor:
        return self.actor(self.normalizer(obs))


class ActorCritic(nn.Module):
    def __init__(
        self, num_actor_obs: int, num_critic_obs: int, num_actions: int, cfg: ActorCriticConfig
    ) -> None:
        super().__init__()
        self.num_actor_obs = num_actor_obs
        self.num_critic_obs = num_critic_obs
        self.num_actions = num_actions
        self.cfg = cfg
        if cfg.normalize_obs:
            self.actor_normalizer: nn.Module = RunningNormalizer(num_actor_obs, clip=cfg.obs_clip)
            self.critic_normalizer: nn.Module = RunningNormalizer(num_critic_obs, clip=cfg.obs_clip)
        else:
            self.actor_normalizer = nn.Identity()
            self.critic_normalizer = nn.Identity()
        # Small output gain: the initial mean is near zero, i.e. the env's default pose.
        self.actor = build_mlp(
            num_actor_obs, cfg.actor_hidden_dims, num_actions, cfg.activation, out_gain=0.01
        )
        self.critic = build_mlp(num_critic_obs, cfg.critic_hidden_dims, 1, cfg.activation, out_gain=1.0)
        log_std = torch.full((num_actions,), float(cfg.init_log_std))
        if cfg.learn_std:
            self.log_std = nn.Parameter(log_std)
        else:
            self.register_buffer("log_std", log_std)

    # --- normalisation -------------------------------------------------------------------------------------
    def normalize_actor_obs(self, obs: Tensor) -> Tensor:
        return self.actor_normalizer(obs)

    def normalize_critic_obs(self, obs: Tensor) -> Tensor:
        return self.critic_normalizer(obs)

    def update_normalizers(self, actor_obs: Tensor, critic_obs: Tensor) -> None:
        """Fold a rollout step into the running statistics (no-op without normalisation or in eval mode)."""
        if isinstance(self.actor_normalizer, RunningNormalizer):
            self.actor_normalizer.update(actor_obs)
            self.critic_normalizer.update(critic_obs)

    # --- on normalised inputs (PPO update) -----------------------------------------------------------------
    def distribution_normalized(self, actor_input: Tensor) -> Normal:
        mean = self.actor(actor_input)
        return Normal(mean, self.log_std.exp().expand_as(mean))

    def value_normalized(self, critic_input: Tensor) -> Tensor:
        return self.critic(critic_input).squeeze(-1)

    # --- on raw observations -------------------------------------------------------------------------------
    def act(self, actor_obs: Tensor) -> Tensor:
        """Sample an action."""
        return self.distribution_normalized(self.normalize_actor_obs(actor_obs)).sample()

    def act_inference(self, actor_obs: Tensor) -> Tensor:
        """The deterministic action (the Gaussian mean), as deployed."""
        return self.actor(self.normalize_actor_obs(actor_obs))

    def evaluate(self, critic_obs: Tensor) -> Tensor:
        """State value, shape (N,)."""
        return self.value_normalized(self.normalize_critic_obs(critic_obs))

    @property
    def action_std(self) -> Tensor:
        return self.log_std.exp()

    def exported_policy(self) -> ExportedPolicy:
        """The deployable part (normaliser + actor mean), sharing this model's weights."""
        return ExportedPolicy(self.actor_normalizer, self.actor)

"""PPO with separate actor/critic optimisers and InterMimic's action-bound loss.

Actor loss   = surrogate_coef * clipped surrogate + bound_loss_coef * bound loss - entropy_coef * entropy
               + extra_actor_loss(obs, mean)          (optional hook, e.g. the DAgger term of distillation)
Critic loss  = (clipped) squared error to the GAE(lambda) returns.
The two networks share nothing, so each has its own Adam and learning rate (Table C: 2e-5 / 1e-4).

Distillation (InterMimic Alg. 1) reuses this class: set `surrogate_coef = w` and
`extra_actor_loss = lambda obs, mean: (1 - w) * ||mean - teacher(obs["teacher"])||`.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from robot_hoi.rl.config import PPOConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.rl.storage import Minibatch, RolloutStorage

ExtraActorLoss = Callable[[dict[str, Tensor], Tensor], Tensor]


def action_bound_loss(mean: Tensor, bound: float) -> Tensor:
    """Mean over the batch of sum over action dims of the squared excess of the mean beyond [-bound, bound]."""
    above = torch.clamp_min(mean - bound, 0.0)
    below = torch.clamp_max(mean + bound, 0.0)
    return (above.square() + below.square()).sum(dim=-1).mean()


def gaussian_kl(mean0: Tensor, std0: Tensor, mean1: Tensor, std1: Tensor) -> Tensor:
    """KL(N0 || N1) for diagonal Gaussians, summed over action dims, averaged over the batch."""
    kl = torch.log(std1 / std0) + (std0.square() + (mean0 - mean1).square()) / (2.0 * std1.square()) - 0.5
    return kl.sum(dim=-1).mean()


class PPO:
    def __init__(self, model: ActorCritic, cfg: PPOConfig, device: torch.device | str = "cpu") -> None:
        self.model = model
        self.cfg = cfg
        self.device = torch.device(device)
        actor_params = list(model.actor.parameters())
        if isinstance(model.log_std, torch.nn.Parameter):
            actor_params.append(model.log_std)
        self.actor_params = actor_params
        self.critic_params = list(model.critic.parameters())
        self.actor_optimizer = torch.optim.Adam(actor_params, lr=cfg.actor_lr)
        self.critic_optimizer = torch.optim.Adam(self.critic_params, lr=cfg.critic_lr)
        self.storage: RolloutStorage | None = None
        self.surrogate_coef = 1.0
        self.extra_actor_loss: ExtraActorLoss | None = None
        # called with every parameter after backward, before clipping: e.g. the gradient all-reduce of
        # data-parallel training (robot_hoi/student/distributed.py)
        self.gradient_hook: Callable[[list[Tensor]], None] | None = None
        self._pending: dict | None = None

    # --- rollout ---------------------------------------------------------------------------------------------
    def init_storage(
        self, num_envs: int, actor_dim: int, critic_dim: int, num_actions: int, extra_obs_dims: dict[str, int]
    ) -> None:
        self.storage = RolloutStorage(
            self.cfg.horizon, num_envs, actor_dim, critic_dim, num_actions, extra_obs_dims, self.device
        )
        self.num_minibatches()  # fail now, not after the first rollout, when the batch cannot be split

    def num_minibatches(self) -> int:
        batch = self.storage.batch_size
        if self.cfg.num_minibatches is not None:
            count = self.cfg.num_minibatches
        else:
            count = batch // self.cfg.minibatch_size
        if count < 1 or count > batch:
            raise ValueError(
                f"ppo: a rollout of {batch} samples (horizon {self.cfg.horizon} x {self.storage.num_envs} envs) "
                f"cannot be split into minibatches of ppo.minibatch_size={self.cfg.minibatch_size} / "
                f"ppo.num_minibatches={self.cfg.num_minibatches}; lower the minibatch size or add envs"
            )
        return count

    @torch.no_grad()
    def act(
        self,
        actor_obs: Tensor,
        critic_obs: Tensor,
        extra_obs: dict[str, Tensor] | None = None,
        actions: Tensor | None = None,
    ) -> Tensor:
        """Choose the actions for one rollout step (sampled, or `actions` if given, e.g. a teacher's).

        Updates the normalisers (in training mode) and remembers what the update will need; call
        `process_env_step` with the env's answer next.
        """
        self.model.update_normalizers(actor_obs, critic_obs)
        actor_input = self.model.normalize_actor_obs(actor_obs)
        critic_input = self.model.normalize_critic_obs(critic_obs)
        dist = self.model.distribution_normalized(actor_input)
        if actions is None:
            actions = dist.sample()
        self._pending = {
            "actor_input": actor_input,
            "critic_input": critic_input,
            "actions": actions,
            "log_probs": dist.log_prob(actions).sum(dim=-1),
            "action_mean": dist.mean,
            "action_std": dist.stddev,
            "values": self.model.value_normalized(critic_input),
            "extra_obs": extra_obs,
        }
        return actions

    @torch.no_grad()
    def process_env_step(
        self, rewards: Tensor, terminated: Tensor, truncated: Tensor, final_critic_obs: Tensor | None = None
    ) -> None:
        """Store the step. Time-outs (truncated, not terminated) are bootstrapped: r += gamma * V(final state).

        final_critic_obs (N, critic_dim) is the pre-reset critic observation (only rows of truncated envs are
        used). Without it V(final state) is approximated by V of the step's own start state, as rsl_rl does.
        Masked arithmetic over all rows: no host sync.
        """
        if self._pending is None:
            raise RuntimeError("process_env_step called without act()")
        pending, self._pending = self._pending, None
        rewards = rewards.to(self.device, torch.float32)
        terminated = terminated.to(self.device, torch.bool)
        truncated = truncated.to(self.device, torch.bool)
        timeouts = truncated & ~terminated
        if final_critic_obs is not None:
            bootstrap = self.model.evaluate(final_critic_obs.to(self.device))
        else:
            bootstrap = pending["values"]
        rewards = rewards + self.cfg.gamma * torch.where(timeouts, bootstrap, 0.0)
        self.storage.add(**pending, rewards=rewards, dones=terminated | truncated)

    @torch.no_grad()
    def compute_returns(self, last_critic_obs: Tensor) -> None:
        self.storage.compute_returns(self.model.evaluate(last_critic_obs), self.cfg.gamma, self.cfg.lam)

    # --- update ----------------------------------------------------------------------------------------------
    def update(self) -> dict[str, float]:
        """Run the mini-epochs over the stored rollout; returns averaged loss and monitoring scalars (the
        minibatches' values stay on the device until one transfer at the end)."""
        cfg = self.cfg
        stats = [self._update_minibatch(batch) for batch in
                 self.storage.minibatches(self.num_minibatches(), cfg.num_epochs, cfg.normalize_advantage)]
        self.storage.clear()
        keys = list(stats[0])
        means = [torch.stack([s[key] for s in stats]).mean() for key in keys]
        values = torch.stack([*means, self.model.action_std.detach().mean()]).tolist()
        result = dict(zip([*keys, "action_std"], values, strict=True))
        result["actor_lr"] = self.actor_lr
        result["critic_lr"] = self.critic_optimizer.param_groups[0]["lr"]
        return result

    def _update_minibatch(self, batch: Minibatch) -> dict[str, Tensor]:
        cfg = self.cfg
        dist = self.model.distribution_normalized(batch.actor_input)
        log_probs = dist.log_prob(batch.actions).sum(dim=-1)
        ratio = torch.exp(log_probs - batch.old_log_probs)
        unclipped = ratio * batch.advantages
        clipped = torch.clamp(ratio, 1.0 - cfg.clip_ratio, 1.0 + cfg.clip_ratio) * batch.advantages
        surrogate = -torch.min(unclipped, clipped).mean()
        bound = action_bound_loss(dist.mean, cfg.action_bound)
        entropy = dist.entropy().sum(dim=-1).mean()
        actor_loss = (
            self.surrogate_coef * surrogate + cfg.bound_loss_coef * bound - cfg.entropy_coef * entropy
        )
        extra = torch.zeros((), device=self.device)
        if self.extra_actor_loss is not None:
            extra = self.extra_actor_loss(batch.extra_obs, dist.mean)
            actor_loss = actor_loss + extra

        values = self.model.value_normalized(batch.critic_input)
        value_loss = (values - batch.returns).square()
        if cfg.clip_value_loss:
            clipped_values = batch.old_values + torch.clamp(
                values - batch.old_values, -cfg.value_clip, cfg.value_clip
            )
            value_loss = torch.max(value_loss, (clipped_values - batch.returns).square())
        value_loss = value_loss.mean()

        self.actor_optimizer.zero_grad(set_to_none=True)
        self.critic_optimizer.zero_grad(set_to_none=True)
        (actor_loss + value_loss).backward()  # disjoint parameters: each loss reaches only its own network
        if self.gradient_hook is not None:
            self.gradient_hook(self.actor_params + self.critic_params)
        max_norm = cfg.max_grad_norm if cfg.max_grad_norm is not None else float("inf")
        actor_grad = torch.nn.utils.clip_grad_norm_(self.actor_params, max_norm)
        critic_grad = torch.nn.utils.clip_grad_norm_(self.critic_params, max_norm)
        self.actor_optimizer.step()
        self.critic_optimizer.step()

        with torch.no_grad():
            kl = gaussian_kl(batch.old_mean, batch.old_std, dist.mean, dist.stddev)
            clip_fraction = ((ratio - 1.0).abs() > cfg.clip_ratio).float().mean()
        if cfg.desired_kl is not None:
            self._adapt_actor_lr(float(kl))  # the adaptive rate needs the KL on the host each minibatch
        detached = {"surrogate_loss": surrogate, "value_loss": value_loss, "bound_loss": bound, "entropy": entropy,
                    "extra_actor_loss": extra, "kl": kl, "clip_fraction": clip_fraction,
                    "actor_grad_norm": actor_grad, "critic_grad_norm": critic_grad}
        return {key: value.detach().float() for key, value in detached.items()}

    def _adapt_actor_lr(self, kl: float) -> None:
        cfg = self.cfg
        lr = self.actor_lr
        if kl > 2.0 * cfg.desired_kl:
            lr = max(cfg.min_lr, lr / 1.5)
        elif 0.0 < kl < 0.5 * cfg.desired_kl:
            lr = min(cfg.max_lr, lr * 1.5)
        for group in self.actor_optimizer.param_groups:
            group["lr"] = lr

    @property
    def actor_lr(self) -> float:
        return float(self.actor_optimizer.param_groups[0]["lr"])

    # --- persistence -----------------------------------------------------------------------------------------
    def optimizer_state(self) -> dict:
        return {"actor": self.actor_optimizer.state_dict(), "critic": self.critic_optimizer.state_dict()}

    def load_optimizer_state(self, state: dict) -> None:
        self.actor_optimizer.load_state_dict(state["actor"])
        self.critic_optimizer.load_state_dict(state["critic"])
        if self.cfg.desired_kl is None:
            # A fixed schedule follows the current config (an override on resume must take effect);
            # an adaptive one continues from where it was.
            for group in self.actor_optimizer.param_groups:
                group["lr"] = self.cfg.actor_lr
        for group in self.critic_optimizer.param_groups:
            group["lr"] = self.cfg.critic_lr

from __future__ import annotations

import pytest
import torch

from robot_hoi.rl.config import ActorCriticConfig, PPOConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.rl.ppo import PPO, action_bound_loss

SMALL = ActorCriticConfig(actor_hidden_dims=[32], critic_hidden_dims=[32], init_log_std=-1.0)


def _ppo(num_envs=8, horizon=4, teacher_dim=0, **ppo_kwargs) -> PPO:
    torch.manual_seed(0)
    model = ActorCritic(3, 4, 2, SMALL)
    cfg = PPOConfig(
        horizon=horizon,
        minibatch_size=None,
        num_minibatches=ppo_kwargs.pop("num_minibatches", 2),
        **ppo_kwargs,
    )
    alg = PPO(model, cfg)
    alg.init_storage(num_envs, 3, 4, 2, {"teacher": teacher_dim} if teacher_dim else {})
    return alg


def _rollout(alg: PPO, teacher_dim: int = 0, scale: float = 1.0) -> None:
    n = alg.storage.num_envs
    for _ in range(alg.cfg.horizon):
        extra = {"teacher": torch.randn(n, teacher_dim)} if teacher_dim else None
        alg.act(torch.randn(n, 3) * scale + 5.0, torch.randn(n, 4) * scale, extra)
        alg.process_env_step(
            torch.randn(n), torch.zeros(n, dtype=torch.bool), torch.zeros(n, dtype=torch.bool)
        )
    alg.compute_returns(torch.randn(n, 4))


def test_action_bound_loss_on_hand_made_case():
    mean = torch.tensor([[1.5, -2.0, 0.3], [0.0, 1.2, -1.0]], requires_grad=True)
    loss = action_bound_loss(mean, 1.1)
    # row 0: 0.4^2 + 0.9^2 = 0.97 ; row 1: 0.1^2 = 0.01 ; mean over rows
    assert float(loss.detach()) == pytest.approx(0.49, abs=1e-6)
    loss.backward()
    # gradient pushes only the out-of-bound entries, inward
    expected_grad = torch.tensor([[0.4, -0.9, 0.0], [0.0, 0.1, 0.0]])  # d/dx of mean over 2 rows of x^2
    assert torch.allclose(mean.grad, expected_grad, atol=1e-6)
    assert float(action_bound_loss(torch.tensor([[1.1, -1.1, 0.0]]), 1.1)) == 0.0


def test_timeouts_bootstrap_from_final_obs_and_terminations_do_not():
    alg = _ppo(num_envs=3, horizon=1)
    alg.model.eval()  # freeze normalisers so evaluate() below sees the same statistics
    alg.act(torch.randn(3, 3), torch.randn(3, 4))
    step_values = alg._pending["values"].clone()
    final = torch.randn(3, 4)
    rewards = torch.tensor([1.0, 2.0, 3.0])
    terminated = torch.tensor([False, True, True])
    truncated = torch.tensor([True, False, True])  # env 2 both: counts as terminated
    alg.process_env_step(rewards, terminated, truncated, final_critic_obs=final)
    v_final = alg.model.evaluate(final).detach()
    expected = torch.tensor([1.0 + 0.99 * float(v_final[0]), 2.0, 3.0])
    assert torch.allclose(alg.storage.rewards[0], expected, atol=1e-6)
    assert torch.equal(alg.storage.dones[0], torch.ones(3))
    # without final obs the step's own value estimate stands in (rsl_rl's approximation)
    alg.storage.clear()
    alg.act(torch.randn(3, 3), torch.randn(3, 4))
    step_values = alg._pending["values"].clone()
    alg.process_env_step(rewards, terminated, truncated)
    assert float(alg.storage.rewards[0, 0]) == pytest.approx(1.0 + 0.99 * float(step_values[0]), abs=1e-6)


def test_stored_inputs_match_the_policy_that_acted():
    """Normalisers move every rollout step; the first minibatch must still see ratio 1 (KL 0)."""
    alg = _ppo(num_minibatches=1, num_epochs=1)
    _rollout(alg, scale=10.0)
    stats = alg.update()
    assert stats["kl"] < 1e-10 and stats["clip_fraction"] == 0.0
    assert float(alg.model.actor_normalizer.count) == 4 * 8


def test_update_changes_both_networks_and_reports_losses():
    alg = _ppo()
    actor_before = [p.detach().clone() for p in alg.model.actor.parameters()]
    critic_before = [p.detach().clone() for p in alg.model.critic.parameters()]
    _rollout(alg)
    stats = alg.update()
    assert alg.storage.step == 0
    for key in ("surrogate_loss", "value_loss", "bound_loss", "entropy", "kl", "actor_lr", "critic_lr"):
        assert key in stats and stats[key] == stats[key]
    assert stats["actor_lr"] == pytest.approx(2e-5) and stats["critic_lr"] == pytest.approx(1e-4)
    assert any(not torch.equal(a, p) for a, p in zip(actor_before, alg.model.actor.parameters(), strict=True))
    assert any(
        not torch.equal(a, p) for a, p in zip(critic_before, alg.model.critic.parameters(), strict=True)
    )


@pytest.mark.slow
def test_extra_actor_loss_hook_is_applied():
    """With the PPO surrogate weighted to 0, only the hook can move the actor: it must pull the mean to a target."""
    target = torch.tensor([0.5, -0.25])
    seen: list[tuple[int, int]] = []

    def imitation(obs: dict[str, torch.Tensor], mean: torch.Tensor) -> torch.Tensor:
        seen.append(tuple(obs["teacher"].shape))
        return (mean - target).square().sum(-1).mean()

    # without the hook (and no bound/entropy pull) the actor does not move
    alg = _ppo(teacher_dim=6, actor_lr=1e-2, bound_loss_coef=0.0)
    alg.surrogate_coef = 0.0
    before = [p.detach().clone() for p in alg.model.actor.parameters()]
    _rollout(alg, teacher_dim=6)
    alg.update()
    assert all(torch.equal(a, p) for a, p in zip(before, alg.model.actor.parameters(), strict=True))

    alg.extra_actor_loss = imitation
    losses = []
    for _ in range(15):
        _rollout(alg, teacher_dim=6)
        losses.append(alg.update()["extra_actor_loss"])
    assert seen[0] == (16, 6)  # minibatch of 32 samples / 2, raw "teacher" group
    assert losses[-1] < 0.05 * losses[0]
    obs = torch.randn(64, 3) + 5.0
    assert torch.allclose(alg.model.act_inference(obs).mean(0), target, atol=0.1)


def test_adaptive_lr_reacts_to_kl():
    alg = _ppo(desired_kl=1e-9, actor_lr=1e-3)
    _rollout(alg)
    alg.update()
    assert alg.actor_lr < 1e-3  # any real step overshoots a tiny KL target
    fixed = _ppo(actor_lr=1e-3)
    _rollout(fixed)
    fixed.update()
    assert fixed.actor_lr == pytest.approx(1e-3)


def test_minibatch_size_larger_than_rollout_is_rejected():
    model = ActorCritic(3, 4, 2, SMALL)
    alg = PPO(model, PPOConfig(horizon=4, minibatch_size=16384))
    with pytest.raises(ValueError, match="minibatch"):
        alg.init_storage(8, 3, 4, 2, {})


def test_given_actions_are_stored_with_their_log_probability():
    """Distillation executes teacher actions at times: act(actions=...) must record exactly those."""
    alg = _ppo(num_envs=4, horizon=1)
    alg.model.eval()
    obs = torch.randn(4, 3)
    chosen = torch.tensor([[0.3, -0.2]]).repeat(4, 1)
    out = alg.act(obs, torch.randn(4, 4), actions=chosen)
    alg.process_env_step(torch.zeros(4), torch.zeros(4, dtype=torch.bool), torch.zeros(4, dtype=torch.bool))
    assert torch.equal(out, chosen) and torch.equal(alg.storage.actions[0], chosen)
    dist = alg.model.distribution_normalized(alg.model.normalize_actor_obs(obs))
    assert torch.allclose(alg.storage.log_probs[0], dist.log_prob(chosen).sum(-1), atol=1e-6)

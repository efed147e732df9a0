from __future__ import annotations

import pytest
import torch

from robot_hoi.rl.storage import RolloutStorage, compute_gae


def test_gae_matches_hand_computed_values_with_termination_and_timeout():
    gamma, lam = 0.9, 0.5
    # env 0 runs through; env 1 terminates at t=0 and times out at t=2, where the caller already folded
    # gamma * V(final state) = 0.9 * 0.7 into the reward (1 + 0.63 = 1.63).
    rewards = torch.tensor([[1.0, 1.0], [2.0, 0.0], [3.0, 1.63]])
    values = torch.tensor([[0.5, 0.2], [1.0, 0.4], [1.5, 0.6]])
    dones = torch.tensor([[0, 1], [0, 0], [0, 1]], dtype=torch.bool)
    last_values = torch.tensor([2.0, 5.0])
    adv, ret = compute_gae(rewards, values, dones, last_values, gamma, lam)
    # env 0: deltas 1.4, 2.35, 3.3 ; A2 = 3.3, A1 = 2.35 + 0.45 * 3.3, A0 = 1.4 + 0.45 * A1
    a1 = 2.35 + 0.45 * 3.3
    expected_env0 = [1.4 + 0.45 * a1, a1, 3.3]
    # env 1: t=2 done: 1.63 - 0.6 ; t=1: 0 + 0.9 * 0.6 - 0.4 + 0.45 * A2 ; t=0 done: 1 - 0.2
    a2 = 1.63 - 0.6
    expected_env1 = [0.8, 0.14 + 0.45 * a2, a2]
    expected = torch.tensor([expected_env0, expected_env1]).T
    assert torch.allclose(adv, expected, atol=1e-6)
    assert torch.allclose(ret, expected + values, atol=1e-6)


def _fill(storage: RolloutStorage, num_actions: int, teacher_dim: int) -> None:
    n = storage.num_envs
    for t in range(storage.horizon):
        storage.add(
            actor_input=torch.full((n, storage.actor_inputs.shape[-1]), float(t)),
            critic_input=torch.randn(n, storage.critic_inputs.shape[-1]),
            actions=torch.randn(n, num_actions),
            log_probs=torch.randn(n),
            action_mean=torch.randn(n, num_actions),
            action_std=torch.ones(num_actions),
            values=torch.randn(n),
            rewards=torch.randn(n),
            dones=torch.zeros(n, dtype=torch.bool),
            extra_obs={"teacher": torch.randn(n, teacher_dim)},
        )


def test_storage_shapes_and_minibatches_cover_each_sample_once_per_epoch():
    horizon, n, actions = 4, 6, 3
    storage = RolloutStorage(
        horizon, n, actor_dim=5, critic_dim=7, num_actions=actions, extra_obs_dims={"teacher": 9}
    )
    assert storage.actor_inputs.shape == (4, 6, 5) and storage.critic_inputs.shape == (4, 6, 7)
    assert storage.extra_obs["teacher"].shape == (4, 6, 9) and storage.actions.shape == (4, 6, 3)
    with pytest.raises(RuntimeError):
        storage.compute_returns(torch.zeros(n), 0.99, 0.95)
    _fill(storage, actions, 9)
    assert storage.full
    with pytest.raises(RuntimeError):
        _fill(storage, actions, 9)
    storage.compute_returns(torch.zeros(n), 0.99, 0.95)
    batches = list(storage.minibatches(num_minibatches=3, num_epochs=2))
    assert len(batches) == 6
    for b in batches:
        assert b.actor_input.shape == (8, 5) and b.critic_input.shape == (8, 7) and b.actions.shape == (8, 3)
        assert (
            b.extra_obs["teacher"].shape == (8, 9) and b.advantages.shape == (8,) and b.returns.shape == (8,)
        )
    # actor_input rows hold their time index: each epoch sees every step exactly n times.
    epoch = torch.cat([b.actor_input[:, 0] for b in batches[:3]])
    assert torch.equal(torch.bincount(epoch.long(), minlength=horizon), torch.full((horizon,), n))
    # normalised advantages: zero mean, unit std over the rollout
    advs = torch.cat([b.advantages for b in batches[:3]])
    assert abs(float(advs.mean())) < 1e-5 and abs(float(advs.std()) - 1.0) < 1e-4
    storage.clear()
    assert storage.step == 0

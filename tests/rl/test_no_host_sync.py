"""The step path reads nothing back to the host: run on torch's `meta` device, where any `.item()`, `bool(...)`,
`nonzero` or boolean-mask read raises, and where mixing in a CPU tensor raises as a CUDA run would."""

from __future__ import annotations

import math

import pytest
import torch

from robot_hoi.rl.config import ActorCriticConfig, PPOConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.rl.ppo import PPO
from robot_hoi.rl.step_log import StepLog

META = torch.device("meta")


def test_meta_catches_host_reads_and_device_mixing():
    x = torch.zeros(3, device=META)
    with pytest.raises(RuntimeError):
        bool(x.any())
    with pytest.raises(RuntimeError):
        x + torch.zeros(3)


def test_ppo_stores_a_step_with_time_outs_without_host_sync():
    model = ActorCritic(3, 4, 2, ActorCriticConfig(actor_hidden_dims=[8], critic_hidden_dims=[8])).to(META)
    alg = PPO(model, PPOConfig(horizon=2, minibatch_size=None, num_minibatches=1), META)
    alg.init_storage(5, 3, 4, 2, {})
    n = 5
    for final in (torch.zeros(n, 4, device=META), None):
        alg._pending = {"actor_input": torch.zeros(n, 3, device=META), "critic_input": torch.zeros(n, 4, device=META),
                        "actions": torch.zeros(n, 2, device=META), "log_probs": torch.zeros(n, device=META),
                        "action_mean": torch.zeros(n, 2, device=META), "action_std": torch.ones(n, 2, device=META),
                        "values": torch.zeros(n, device=META), "extra_obs": None}
        truncated = torch.zeros(n, dtype=torch.bool, device=META)
        alg.process_env_step(torch.zeros(n, device=META), torch.zeros(n, dtype=torch.bool, device=META), truncated,
                             final)
    assert alg.storage.full and alg.storage.rewards.device.type == "meta"


def test_step_log_sums_on_the_device_and_averages_over_the_values_given():
    meta_log = StepLog(META)
    meta_log.add("Metrics/success", torch.full((4,), math.nan, device=META))  # no sync on the step path
    meta_log.add("Metrics/success", torch.zeros((), device=META))
    log = StepLog("cpu")
    log.add("Metrics/success", torch.tensor([1.0, math.nan, 0.0, math.nan]))  # envs 1 and 3: no episode ended
    log.add("Metrics/success", torch.tensor([math.nan, 1.0, math.nan, math.nan]))
    log.add("Episode_Reward/x", 2.0)
    log.add("Metrics/never", torch.full((3,), math.nan))
    means, returns = log.to_host(torch.tensor([[math.nan, 3.0], [5.0, math.nan]]))
    assert means == {"Metrics/success": pytest.approx(2 / 3), "Episode_Reward/x": 2.0}
    assert returns == [3.0, 5.0]

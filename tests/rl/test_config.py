from __future__ import annotations

import pytest

from robot_hoi.errors import UserError
from robot_hoi.rl.config import DEFAULT_PPO_CONFIG, FAST_PPO_CONFIG, TrainConfig, load_train_config


def test_paper_config_is_intermimic_table_c():
    cfg = load_train_config(DEFAULT_PPO_CONFIG)
    assert cfg == TrainConfig()  # the YAML and the dataclass defaults say the same thing
    ppo = cfg.ppo
    assert (ppo.gamma, ppo.lam, ppo.entropy_coef) == (0.99, 0.95, 0.0)
    assert (ppo.actor_lr, ppo.critic_lr) == (2e-5, 1e-4)
    assert (ppo.minibatch_size, ppo.horizon, ppo.bound_loss_coef) == (16384, 32, 10.0)
    assert cfg.model.actor_hidden_dims == [1024, 1024, 512] == cfg.model.critic_hidden_dims
    assert not cfg.model.learn_std and cfg.model.init_log_std == -2.9


def test_fast_preset_loads_and_round_trips_through_json():
    cfg = load_train_config(FAST_PPO_CONFIG, ["ppo.actor_lr=1e-4", "model.activation=relu"])
    assert cfg.ppo.actor_lr == 1e-4 and cfg.ppo.num_minibatches == 4 and cfg.ppo.minibatch_size is None
    assert TrainConfig.from_json(cfg.to_json()) == cfg


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["ppo.actor_learning_rate=1e-4"], "actor_learning_rate"),
        (["ppo.num_minibatches=4"], "exactly one"),
        (["model.activation=gelu"], "activation"),
        (["ppo.gamma=1.5"], "gamma"),
        (["runner.actor_obs_groups=[]"], "actor_obs_groups"),
    ],
)
def test_bad_settings_are_rejected(overrides, message):
    with pytest.raises(UserError, match=message):
        load_train_config(DEFAULT_PPO_CONFIG, overrides)

"""robot_hoi/utils/timing.py: laps and sections add up; OFF does nothing; the runner attributes its stages."""

from __future__ import annotations

import time

import torch

from robot_hoi.rl.budget import Budget
from robot_hoi.rl.config import FAST_PPO_CONFIG, load_train_config
from robot_hoi.rl.dummy_env import ReachEnv
from robot_hoi.rl.runner import OnPolicyRunner
from robot_hoi.utils.timing import OFF, Timers


def test_laps_and_sections_accumulate_by_name():
    calls = []
    timers = Timers(sync=lambda: calls.append(1))
    timers.start()
    time.sleep(0.01)
    timers.lap("a")
    timers.lap("b")
    timers.start()
    time.sleep(0.01)
    timers.lap("a")
    with timers.section("c"):
        time.sleep(0.01)
    assert timers.seconds["a"] >= 0.02 and 0 <= timers.seconds["b"] < 0.01 and timers.seconds["c"] >= 0.01
    assert calls  # the sync hook runs at every boundary
    timers.reset()
    assert timers.seconds == {}


def test_off_does_nothing():
    OFF.start()
    OFF.lap("x")
    with OFF.section("y"):
        pass
    assert not hasattr(OFF, "seconds")


def test_runner_splits_its_wall_time():
    torch.set_num_threads(1)
    cfg = load_train_config(FAST_PPO_CONFIG, ["runner.progress=false", "runner.tensorboard=false", "ppo.horizon=8",
                                              "model.actor_hidden_dims=[16]", "model.critic_hidden_dims=[16]"])
    runner = OnPolicyRunner(ReachEnv(num_envs=16), cfg, None)
    runner.timers = timers = Timers()
    start = time.perf_counter()
    runner.learn(Budget(iterations=2))
    wall = time.perf_counter() - start
    assert set(timers.seconds) == {"policy", "storage", "update", "logging"}
    assert 0 < sum(timers.seconds.values()) <= wall

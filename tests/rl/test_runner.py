from __future__ import annotations

import json

import pytest
import torch

from robot_hoi.errors import UserError
from robot_hoi.rl.budget import Budget
from robot_hoi.rl.checkpoint import load_policy, read_checkpoint
from robot_hoi.rl.config import FAST_PPO_CONFIG, load_train_config
from robot_hoi.rl.dummy_env import ReachEnv
from robot_hoi.rl.logger import MemoryWriter
from robot_hoi.rl.runner import OnPolicyRunner

TINY = [
    "runner.progress=false",
    "runner.tensorboard=false",
    "model.actor_hidden_dims=[64, 64]",
    "model.critic_hidden_dims=[64, 64]",
    "ppo.horizon=16",
]


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny nets: threading only adds overhead on the shared 2-core machine
    yield
    torch.set_num_threads(threads)


def _runner(log_dir=None, overrides=(), num_envs=64, seed=0):
    cfg = load_train_config(FAST_PPO_CONFIG, [*TINY, *overrides])
    memory = MemoryWriter()
    env = ReachEnv(num_envs=num_envs, max_episode_length=32, seed=seed)
    return OnPolicyRunner(env, cfg, log_dir, writers=[memory]), memory


def test_runner_learns_reach_task():
    runner, memory = _runner()
    result = runner.learn(Budget(iterations=30))
    returns = [v for _, v in memory.scalars["Train/mean_return"]]
    # A random policy wanders off (first-iteration returns -13 .. 7 over seeds); reaching and holding the target
    # scores ~26 of at most 32.
    assert result["mean_return"] > 20.0
    assert result["mean_return"] > returns[0] + 10.0
    assert result["iterations"] == 30 and result["samples"] == 30 * 16 * 64
    # env "log" scalars and per-episode stats are aggregated and written
    assert "Episode_Reward/progress" in memory.scalars and "Metrics/within_0.1" in memory.scalars
    assert memory.last("Episode/final_distance") < 0.3
    for name in (
        "Loss/surrogate",
        "Loss/value",
        "Loss/action_bound",
        "LR/actor",
        "LR/critic",
        "Train/mean_episode_length",
        "Perf/samples_per_s",
        "Perf/collection_s",
        "Perf/learning_s",
    ):
        assert name in memory.scalars, name


def test_initialise_from_takes_weights_and_normalisers_but_not_counters(tmp_path):
    runner, _ = _runner(tmp_path / "base")
    runner.learn(Budget(iterations=3))
    ckpt = runner.save(tmp_path / "base" / "model_3.pt")
    fresh, _ = _runner(tmp_path / "clip", seed=1)
    fresh.initialise_from(ckpt)
    for (name, a), (_, b) in zip(runner.model.state_dict().items(), fresh.model.state_dict().items(), strict=True):
        assert torch.equal(a, b), name
    assert fresh.iteration == 0 and fresh.total_samples == 0  # a new run: its own budget, schedule and curriculum
    assert not fresh.alg.actor_optimizer.state_dict()["state"]
    # a checkpoint of another observation layout with the same sizes is refused
    data = read_checkpoint(ckpt)
    data["obs_layout"]["actor_groups"] = ["student"]
    torch.save(data, tmp_path / "other.pt")
    with pytest.raises(UserError, match="observation layout"):
        fresh.initialise_from(tmp_path / "other.pt")


def test_checkpoint_resume_restores_everything_and_continues(tmp_path):
    runner, _ = _runner(tmp_path / "a", ["runner.save_interval=2", "runner.keep_last=2"])
    runner.learn(Budget(iterations=5))
    # periodic checkpoints at 2 and 4, pruned to the last 2, plus the final one at 5
    assert sorted(p.name for p in (tmp_path / "a").glob("model_*.pt")) == ["model_4.pt", "model_5.pt"]
    assert (tmp_path / "a" / "scalars.jsonl").read_text().count("\n") == 5
    info = json.loads((tmp_path / "a" / "run_info.json").read_text())
    assert info["obs_layout"]["actor_groups"] == ["policy"] and info["num_actions"] == 2
    ckpt = tmp_path / "a" / "model_5.pt"
    data = read_checkpoint(ckpt)
    assert data["iteration"] == 5 and data["total_samples"] == 5 * 16 * 64
    assert json.loads(data["config_json"])["ppo"]["num_minibatches"] == 4

    resumed, _ = _runner(tmp_path / "b", seed=1)
    resumed.resume(ckpt)
    for (name, a), (_, b) in zip(
        runner.model.state_dict().items(), resumed.model.state_dict().items(), strict=True
    ):
        assert torch.equal(a, b), name
    assert resumed.iteration == 5 and resumed.total_samples == runner.total_samples
    opt_a, opt_b = runner.alg.actor_optimizer.state_dict(), resumed.alg.actor_optimizer.state_dict()
    for key, state in opt_a["state"].items():
        assert torch.equal(state["exp_avg_sq"], opt_b["state"][key]["exp_avg_sq"])
    count_before = float(resumed.model.actor_normalizer.count)
    assert count_before == float(runner.model.actor_normalizer.count) > 0

    resumed.learn(Budget(iterations=2))
    assert resumed.iteration == 7
    assert float(resumed.model.actor_normalizer.count) > count_before
    assert (tmp_path / "b" / "model_7.pt").is_file()

    model, cfg, data = load_policy(ckpt)
    assert not model.training and cfg.ppo.num_minibatches == 4
    obs = torch.randn(3, 4)
    assert torch.equal(model.act_inference(obs), runner.model.act_inference(obs))


def test_bad_checkpoints_are_user_errors(tmp_path):
    runner, _ = _runner()
    with pytest.raises(UserError, match="not found"):
        runner.resume(tmp_path / "missing.pt")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(UserError, match="junk.pt"):
        runner.resume(junk)
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(2)}, other)
    with pytest.raises(UserError, match="not a robot-hoi PPO checkpoint"):
        runner.load(other)
    # a checkpoint from an env with other observation sizes
    good = runner.save(tmp_path / "good.pt")
    cfg = load_train_config(FAST_PPO_CONFIG, TINY)
    wider = OnPolicyRunner(ReachEnv(num_envs=8, dim=3), cfg, None)
    with pytest.raises(UserError, match="do not match"):
        wider.load(good)


def test_missing_observation_group_and_unsplittable_batch_are_user_errors():
    env = ReachEnv(num_envs=4)
    with pytest.raises(UserError, match="offers"):
        OnPolicyRunner(
            env, load_train_config(FAST_PPO_CONFIG, [*TINY, "runner.critic_obs_groups=[privileged]"]), None
        )
    with pytest.raises(UserError, match="minibatch"):
        OnPolicyRunner(env, load_train_config(overrides=TINY), None)  # Table C's 16384 > 16 x 4 samples


def test_tensorboard_and_wall_budget(tmp_path):
    runner, memory = _runner(tmp_path, ["runner.tensorboard=true"], num_envs=8)
    result = runner.learn(Budget(wall_seconds=0.5))
    runner.close()
    assert result["iterations"] >= 1 and result["wall_s"] < 5.0
    assert list(tmp_path.glob("events.out.tfevents.*"))
    lines = (tmp_path / "scalars.jsonl").read_text().splitlines()
    assert len(lines) == result["iterations"] and "Loss/value" in json.loads(lines[-1])


def test_subclass_hooks_drive_the_rollout():
    """The distillation runner's extension points: a per-iteration hook and the executed actions."""

    class ZeroActionRunner(OnPolicyRunner):
        started: list[int] = []

        def _on_iteration_start(self) -> None:
            self.started.append(self.iteration)

        def _select_actions(self, actor_obs, critic_obs, extra_obs):
            return self.alg.act(actor_obs, critic_obs, extra_obs, actions=torch.zeros(actor_obs.shape[0], 2))

    cfg = load_train_config(FAST_PPO_CONFIG, TINY)
    runner = ZeroActionRunner(ReachEnv(num_envs=8, max_episode_length=32), cfg, None)
    runner.learn(Budget(iterations=3))
    assert runner.started == [0, 1, 2]
    # standing still never leaves the arena: every episode runs to the time-out
    assert set(runner.recent_lengths) == {32.0}


def test_interrupt_saves_a_checkpoint_and_reraises(tmp_path):
    class InterruptedRunner(OnPolicyRunner):
        def _on_iteration_start(self) -> None:
            if self.iteration == 2:
                raise KeyboardInterrupt

    cfg = load_train_config(FAST_PPO_CONFIG, TINY)
    runner = InterruptedRunner(ReachEnv(num_envs=8), cfg, tmp_path)
    with pytest.raises(KeyboardInterrupt):
        runner.learn(Budget(iterations=10))
    runner.close()
    assert read_checkpoint(tmp_path / "model_2.pt")["iteration"] == 2


@pytest.mark.slow
def test_update_runs_on_the_physics_threads_and_the_rollout_keeps_its_own():
    """The PPO update takes the physics pool's threads (idle while it runs), the rollout keeps torch's setting."""
    from types import SimpleNamespace

    runner, _ = _runner(num_envs=8)
    runner.env.backend = SimpleNamespace(nthread=2)  # a CPU physics pool of 2 threads
    seen = []
    update = runner.alg.update
    runner.alg.update = lambda: seen.append(torch.get_num_threads()) or update()
    runner.learn(Budget(iterations=2))
    assert seen == [2, 2] and torch.get_num_threads() == 1
    explicit, _ = _runner(num_envs=8, overrides=["runner.update_threads=3"])
    assert explicit._update_threads() == 3
    with pytest.raises(UserError, match="update_threads must be positive"):
        _runner(overrides=["runner.update_threads=0"])


def test_in_training_evaluation_keeps_the_best_policy_and_its_curve(tmp_path):
    runner, memory = _runner(tmp_path, ["runner.eval_interval=2", "runner.save_interval=100"])
    # second is best: success ranks before duration; the third's interaction success before the second's duration
    scores = iter([(0.0, 0.0, 3.0), (0.5, 0.0, 2.0), (0.5, 0.25, 1.0), (0.25, 0.25, 9.0), (0.5, 0.0, 9.0)])
    seen = []

    def evaluator(model):
        assert not model.training  # the policy mean is scored, normalisers frozen
        success, interaction, duration = next(scores)
        return {"success_rate": success, "interaction_success_rate": interaction, "duration_s": duration}

    runner.evaluator = evaluator
    runner.on_evaluation = seen.append
    runner.learn(Budget(iterations=10))
    assert runner.model.training
    rows = [json.loads(line) for line in (tmp_path / "eval_curve.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [2, 4, 6, 8, 10] and rows == seen
    assert [r["best"] for r in rows] == [True, True, True, False, False]
    assert [v for _, v in memory.scalars["Eval/success_rate"]] == [0.0, 0.5, 0.5, 0.25, 0.5]
    best = read_checkpoint(tmp_path / "model_best.pt")
    assert best["iteration"] == 6 and best["eval"]["interaction_success_rate"] == 0.25

    # a resumed run measures against the run's best, not against nothing
    resumed, _ = _runner(tmp_path, ["runner.eval_interval=2", "runner.save_interval=100"])
    resumed.resume(tmp_path / "model_10.pt")
    resumed.evaluator = lambda model: {"success_rate": 0.25, "duration_s": 50.0}
    assert resumed.evaluate_and_keep_best()["best"] is False
    assert read_checkpoint(tmp_path / "model_best.pt")["iteration"] == 6

    # validated otherwise (the run now trains with domain randomisation): the old best is not compared with
    randomized = {"success_rate": 0.25, "duration_s": 5.0, "validation": "training randomization"}
    resumed.evaluator = lambda model: dict(randomized)
    assert resumed.evaluate_and_keep_best()["best"] is True
    assert read_checkpoint(tmp_path / "model_best.pt")["eval"]["validation"] == "training randomization"
    resumed.evaluator = lambda model: {**randomized, "success_rate": 0.125}
    assert resumed.evaluate_and_keep_best()["best"] is False  # rows validated alike are ranked as before

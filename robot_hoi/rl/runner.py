"""On-policy training loop: rollouts from a VecEnv, PPO updates, logging, progress, checkpoints and resume.

    runner = OnPolicyRunner(env, load_train_config(), log_dir="runs/teacher_sub2", device="cuda")
    runner.learn(parse_budget("2h"))       # or Budget(samples=5_000_000), "300it", "2h,50M" (first limit wins)
    runner.resume("runs/teacher_sub2/model_1500.pt"); runner.learn(parse_budget("1h"))

Run folder: model_<iteration>.pt checkpoints, scalars.jsonl (every logged scalar, one line per iteration),
TensorBoard events, run_info.json (resolved config, obs layout, git commit) and git.diff. With an evaluator and
runner.eval_interval: eval_curve.jsonl (one row per evaluation) and model_best.pt.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from deploy.atomic import atomic_write_text
from robot_hoi.errors import UserError
from robot_hoi.rl.budget import Budget
from robot_hoi.rl.checkpoint import (
    BEST_CHECKPOINT,
    git_state,
    load_model_state,
    prune_checkpoints,
    read_checkpoint,
    save_checkpoint,
)
from robot_hoi.rl.config import TrainConfig
from robot_hoi.rl.env import VecEnv, concat_groups, group_dim
from robot_hoi.rl.eval_curve import EVAL_CURVE_FILE, eval_rank
from robot_hoi.rl.logger import JsonlWriter, Logger, LogWriter, TensorBoardWriter
from robot_hoi.rl.models import ActorCritic
from robot_hoi.rl.ppo import PPO
from robot_hoi.rl.progress import progress_text, training_progress
from robot_hoi.rl.step_log import StepLog
from robot_hoi.utils.threads import torch_threads
from robot_hoi.utils.timing import OFF

_PPO_SCALARS = {
    "surrogate_loss": "Loss/surrogate",
    "value_loss": "Loss/value",
    "bound_loss": "Loss/action_bound",
    "entropy": "Loss/entropy",
    "extra_actor_loss": "Loss/extra_actor",
    "kl": "Policy/kl",
    "clip_fraction": "Policy/clip_fraction",
    "action_std": "Policy/action_std",
    "actor_grad_norm": "Policy/actor_grad_norm",
    "critic_grad_norm": "Policy/critic_grad_norm",
    "actor_lr": "LR/actor",
    "critic_lr": "LR/critic",
}


class OnPolicyRunner:
    def __init__(
        self,
        env: VecEnv,
        cfg: TrainConfig,
        log_dir: str | Path | None,
        device: str | torch.device = "cpu",
        writers: list[LogWriter] | None = None,
    ) -> None:
        self.env = env
        self.cfg = cfg
        self.device = torch.device(device)
        self.log_dir = Path(log_dir) if log_dir is not None else None
        self.on_checkpoint: Callable[[Path], None] | None = None  # after each periodic save (Ray mirroring)
        # policy (eval mode) -> metrics with success_rate and duration_s; run every runner.eval_interval iterations
        self.evaluator: Callable[[ActorCritic], dict[str, float]] | None = None
        self.on_evaluation: Callable[[dict[str, Any]], None] | None = None  # after each evaluation, with its row
        self.best_eval: dict[str, Any] | None = None  # the row of model_best.pt
        # a robot_hoi.utils.timing.Timers (shared with the env) splits the loop's wall time into stages
        self.timers = OFF
        torch.manual_seed(cfg.seed)
        rc = cfg.runner
        self.actor_dim = group_dim(env, rc.actor_obs_groups, "actor")
        self.critic_dim = group_dim(env, rc.critic_obs_groups, "critic")
        group_dim(env, rc.extra_obs_groups, "extra")
        extra_dims = {g: int(env.obs_dims[g]) for g in rc.extra_obs_groups}
        self.model = ActorCritic(self.actor_dim, self.critic_dim, env.num_actions, cfg.model).to(self.device)
        self.alg = PPO(self.model, cfg.ppo, self.device)
        try:
            self.alg.init_storage(env.num_envs, self.actor_dim, self.critic_dim, env.num_actions, extra_dims)
        except ValueError as exc:
            raise UserError(str(exc)) from None

        self.iteration = 0
        self.total_samples = 0
        self.total_time_s = 0.0
        self._obs: dict[str, Tensor] | None = None
        self._git_cache: dict[str, str] | None = None
        self._ep_return = torch.zeros(env.num_envs, device=self.device)
        self._ep_length = torch.zeros(env.num_envs, device=self.device)
        self.recent_returns: deque[float] = deque(maxlen=rc.episode_window)
        self.recent_lengths: deque[float] = deque(maxlen=rc.episode_window)

        all_writers: list[LogWriter] = list(writers or [])
        if self.log_dir is not None:
            all_writers.append(JsonlWriter(self.log_dir / "scalars.jsonl"))
            if rc.tensorboard:
                all_writers.append(TensorBoardWriter(self.log_dir))
        self.logger = Logger(all_writers)

    # --- observation plumbing ----------------------------------------------------------------------------------
    def _to_device(self, obs: dict[str, Tensor]) -> dict[str, Tensor]:
        return {k: v.to(self.device, torch.float32) for k, v in obs.items()}

    def _split(self, obs: dict[str, Tensor]) -> tuple[Tensor, Tensor, dict[str, Tensor]]:
        rc = self.cfg.runner
        extra = {g: obs[g] for g in rc.extra_obs_groups}
        return concat_groups(obs, rc.actor_obs_groups), concat_groups(obs, rc.critic_obs_groups), extra

    def _select_actions(self, actor_obs: Tensor, critic_obs: Tensor, extra_obs: dict[str, Tensor]) -> Tensor:
        """Actions executed in the rollout. Distillation overrides this to execute teacher actions at times."""
        return self.alg.act(actor_obs, critic_obs, extra_obs)

    def _on_iteration_start(self) -> None:
        """Called before each rollout (self.iteration = iterations done). Distillation sets its w schedule here."""

    def _on_iteration_end(self) -> None:
        """Called after each update (self.iteration counts it). Distillation averages its weights here."""

    def evaluation_model(self):
        """The policy the evaluator scores and model_best.pt stands for (distillation: its weight average)."""
        return self.model

    # --- training ----------------------------------------------------------------------------------------------
    def _update_threads(self) -> int | None:
        """Threads for the PPO update on the CPU: the config's, else the physics pool's (idle meanwhile)."""
        if self.device.type != "cpu":
            return None
        if self.cfg.runner.update_threads is not None:
            return self.cfg.runner.update_threads
        return getattr(getattr(self.env, "backend", None), "nthread", None)

    def learn(self, budget: Budget) -> dict[str, float]:
        """Train until `budget` (counted from this call) is used up; checkpoints periodically and at the end."""
        if self._obs is None:
            self._obs = self._to_device(self.env.reset())
        self.model.train()
        self._write_run_info()
        start = time.monotonic()
        first_iteration, first_samples = self.iteration, self.total_samples
        progress = training_progress(self.cfg.runner.progress)  # plain lines when stdout is not a terminal
        last_saved = -1
        try:
            with progress:
                task = progress.add_task(f"PPO, budget {budget.describe()}", total=1000)
                last_saved = self._train_loop(budget, progress, task, start)
        except KeyboardInterrupt:
            self._save_periodic()  # keep what was learnt; the interrupted rollout is simply dropped
            self.alg.storage.clear()
            raise
        if last_saved != self.iteration:
            self._save_periodic()
        self.logger.flush()
        return {
            "iterations": float(self.iteration - first_iteration),
            "samples": float(self.total_samples - first_samples),
            "wall_s": time.monotonic() - start,
            "mean_return": self.mean_return(),
        }

    def _train_loop(self, budget: Budget, progress, task, start: float) -> int:
        """Iterate until the budget is spent; returns the iteration of the last periodic checkpoint (-1: none)."""
        batch = self.alg.storage.batch_size
        samples = iterations = 0
        last_saved = -1
        self.timers.start()
        while True:
            self._on_iteration_start()
            curriculum = self._update_curriculum()
            t0 = time.monotonic()
            env_logs = self._rollout()
            self.timers.lap("logging")  # the rollout's one read-back of its log values
            env_logs.update(curriculum)
            t1 = time.monotonic()
            with torch_threads(self._update_threads()):
                stats = self.alg.update()
            t2 = time.monotonic()
            self.timers.lap("update")
            self.iteration += 1
            self._on_iteration_end()
            iterations += 1
            samples += batch
            self.total_samples += batch
            self.total_time_s += t2 - t0
            if self.iteration % self.cfg.runner.physics_check_interval == 0:
                env_logs.update(self.physics_report())
            scalars = self._log(stats, env_logs, collection_s=t1 - t0, learning_s=t2 - t1)
            if self.iteration % self.cfg.runner.save_interval == 0:
                self._save_periodic()
                last_saved = self.iteration
            if self.evaluator is not None and self.cfg.runner.eval_interval and \
                    self.iteration % self.cfg.runner.eval_interval == 0:
                self.evaluate_and_keep_best()
            elapsed = time.monotonic() - start
            progress.update(
                task,
                completed=int(1000 * budget.fraction_done(elapsed, samples, iterations)),
                description=progress_text(self.iteration, batch / max(t2 - t0, 1e-9), scalars),
            )
            self.timers.lap("logging")
            if budget.exhausted(elapsed, samples, iterations):
                break
        return last_saved

    def evaluate_and_keep_best(self) -> dict[str, Any]:
        """Score the current policy with the evaluator; log it, and save it as model_best.pt when it beats the best
        so far (eval_curve.eval_rank: success, interaction success, tracked duration). Returns the curve row."""
        started = time.monotonic()
        model = self.evaluation_model()
        was_training = model.training
        model.eval()
        try:
            metrics = self.evaluator(model)
        finally:
            model.train(was_training)
        row = {"step": self.iteration, "samples": self.total_samples, "train_time_s": round(self.total_time_s, 1),
               "eval_s": round(time.monotonic() - started, 2), **metrics}
        # a best validated otherwise (a run resumed with other settings) is not compared with: this row replaces it
        comparable = self.best_eval is not None and self.best_eval.get("validation") == metrics.get("validation")
        row["best"] = not comparable or eval_rank(metrics) > eval_rank(self.best_eval)
        if row["best"]:
            self.best_eval = row
            if self.log_dir is not None:
                self.save(self.log_dir / BEST_CHECKPOINT, extra={"eval": row})
        if self.log_dir is not None:  # an append-only log like scalars.jsonl (trimmed the same way on resume)
            with (self.log_dir / EVAL_CURVE_FILE).open("a", encoding="utf-8") as curve:
                curve.write(json.dumps(row) + "\n")
        self.logger.log_scalars({f"Eval/{k}": float(v) for k, v in metrics.items()
                                 if isinstance(v, (int, float)) and not isinstance(v, bool)}, self.iteration)
        if self.on_evaluation is not None:
            self.on_evaluation(row)
        return row

    def _update_curriculum(self) -> dict[str, float]:
        """Envs with a training curriculum (e.g. assist wrenches) follow the samples trained so far."""
        update = getattr(self.env, "update_curriculum", None)
        return update(self.total_samples) if update is not None else {}

    @torch.no_grad()
    def _rollout(self) -> dict[str, float]:
        """One horizon of env steps into the storage. Nothing is read back to the host per step: log values and
        finished episodes stay on the device until one transfer at the end (StepLog.to_host)."""
        log = StepLog(self.device)
        ended_returns: list[Tensor] = []
        ended_lengths: list[Tensor] = []
        critic_groups = self.cfg.runner.critic_obs_groups
        for _ in range(self.cfg.ppo.horizon):
            actor_obs, critic_obs, extra_obs = self._split(self._obs)
            actions = self._select_actions(actor_obs, critic_obs, extra_obs)
            self.timers.lap("policy")
            obs, rewards, terminated, truncated, extras = self.env.step(actions.to(self.env.device))
            rewards = rewards.to(self.device, torch.float32)
            terminated = terminated.to(self.device, torch.bool)
            truncated = truncated.to(self.device, torch.bool)
            final_obs = extras.get("final_obs")
            final_critic = None
            if final_obs is not None and all(g in final_obs for g in critic_groups):
                final_critic = concat_groups(self._to_device(final_obs), critic_groups)
            self.alg.process_env_step(rewards, terminated, truncated, final_critic)
            self._obs = self._to_device(obs)

            self._ep_return += rewards
            self._ep_length += 1
            done = terminated | truncated
            ended_returns.append(torch.where(done, self._ep_return, torch.nan))
            ended_lengths.append(torch.where(done, self._ep_length, torch.nan))
            self._ep_return.masked_fill_(done, 0.0)
            self._ep_length.masked_fill_(done, 0.0)
            for name, value in extras.get("log", {}).items():
                log.add(name, value)
            for name, value in extras.get("episode_done", {}).items():
                log.add(f"Episode/{name}", value)
            self.timers.lap("storage")
        self.alg.compute_returns(concat_groups(self._obs, critic_groups))
        self.timers.lap("update")
        means, returns, lengths = log.to_host(torch.stack(ended_returns), torch.stack(ended_lengths))
        self.recent_returns.extend(returns)
        self.recent_lengths.extend(lengths)
        return means

    def physics_report(self) -> dict[str, float]:
        """The physics backend's health scalars (warp: overflow flags, buffer use), read every
        runner.physics_check_interval iterations; raises when a buffer overflowed."""
        report = getattr(getattr(self.env, "backend", None), "physics_report", None)
        return report() if report is not None else {}

    def mean_return(self) -> float:
        """Mean undiscounted return of the last `episode_window` finished episodes (nan before any finished)."""
        return sum(self.recent_returns) / len(self.recent_returns) if self.recent_returns else float("nan")

    def _log(
        self, stats: dict[str, float], env_logs: dict[str, float], collection_s: float, learning_s: float
    ) -> dict[str, float]:
        batch = self.alg.storage.batch_size
        scalars = {_PPO_SCALARS.get(k, f"Loss/{k}"): v for k, v in stats.items()}
        if self.recent_returns:
            scalars["Train/mean_return"] = self.mean_return()
            scalars["Train/mean_episode_length"] = sum(self.recent_lengths) / len(self.recent_lengths)
        scalars["Perf/samples_per_s"] = batch / max(collection_s + learning_s, 1e-9)
        scalars["Perf/collection_s"] = collection_s
        scalars["Perf/learning_s"] = learning_s
        scalars["Perf/total_samples"] = float(self.total_samples)
        scalars.update(env_logs)
        self.logger.log_scalars(scalars, self.iteration)
        return scalars

    # --- checkpoints -------------------------------------------------------------------------------------------
    def _git(self) -> dict[str, str]:
        if self._git_cache is None:
            self._git_cache = git_state()
        return self._git_cache

    def obs_layout(self) -> dict:
        rc = self.cfg.runner
        return {
            "actor_groups": list(rc.actor_obs_groups),
            "critic_groups": list(rc.critic_obs_groups),
            "obs_dims": {k: int(v) for k, v in self.env.obs_dims.items()},
        }

    def _write_run_info(self) -> None:
        if self.log_dir is None:
            return
        git = self._git()
        info = {
            "config": json.loads(self.cfg.to_json()),
            "obs_layout": self.obs_layout(),
            "num_envs": self.env.num_envs,
            "num_actions": self.env.num_actions,
            "git_commit": git["commit"],
        }
        atomic_write_text(self.log_dir / "run_info.json", json.dumps(info, indent=2) + "\n")
        atomic_write_text(self.log_dir / "git.diff", git["diff"])

    def _save_periodic(self) -> None:
        if self.log_dir is None:
            return
        path = self.save(self.log_dir / f"model_{self.iteration}.pt")
        prune_checkpoints(self.log_dir, self.cfg.runner.keep_last)
        if self.on_checkpoint is not None:
            self.on_checkpoint(path)

    def save(self, path: str | Path, extra: dict[str, Any] | None = None) -> Path:
        git = self._git()
        return save_checkpoint(
            path,
            (extra or {}) | {
                "model": self.model.state_dict(),
                "optimizer": self.alg.optimizer_state(),
                "iteration": self.iteration,
                "total_samples": self.total_samples,
                "total_time_s": self.total_time_s,
                "config_json": self.cfg.to_json(),
                "dims": {
                    "actor_obs": self.actor_dim,
                    "critic_obs": self.critic_dim,
                    "num_actions": self.env.num_actions,
                },
                "obs_layout": self.obs_layout(),
                "git_commit": git["commit"],
                "git_diff": git["diff"],
                "torch_rng_state": torch.get_rng_state(),
                "curriculum": getattr(self.env, "curriculum_state", dict)(),
            },
        )

    def load(self, path: str | Path, load_optimizer: bool = False) -> dict[str, Any]:
        """Load model weights and normaliser statistics (and optionally the optimisers) from a checkpoint."""
        data = read_checkpoint(path, map_location=self.device)
        dims = data["dims"]
        ours = {
            "actor_obs": self.actor_dim,
            "critic_obs": self.critic_dim,
            "num_actions": self.env.num_actions,
        }
        if {k: int(dims.get(k, -1)) for k in ours} != ours:
            raise UserError(f"{path}: checkpoint dims {dict(dims)} do not match this env/config {ours}")
        load_model_state(self.model, data["model"], path)
        if load_optimizer:
            if "optimizer" not in data:
                raise UserError(f"{path}: checkpoint has no optimizer state to resume from")
            self.alg.load_optimizer_state(data["optimizer"])
        return data

    def init_mismatch(self, path: str | Path) -> str | None:
        """Why another run's policy cannot start this one (None when it can): its observation layout must be ours,
        else the same sizes would feed the wrong numbers to the wrong inputs, and every tensor must fit our model."""
        data = read_checkpoint(path)
        theirs, ours = data.get("obs_layout"), self.obs_layout()
        if theirs != ours:
            return f"its observation layout {theirs} is not this run's {ours}"
        shapes = {k: tuple(v.shape) for k, v in self.model.state_dict().items()}
        stored = {k: tuple(v.shape) for k, v in data["model"].items() if isinstance(v, Tensor)}
        if stored != shapes:
            differ = sorted(k for k in shapes.keys() | stored.keys() if shapes.get(k) != stored.get(k))
            return f"its network differs from this run's in {', '.join(differ[:4])}"
        return None

    def initialise_from(self, path: str | Path, required: bool = True) -> str | None:
        """Start from another run's policy (weights and normalisers only). When it does not fit: UserError if it was
        `required`, else nothing is loaded and the reason is returned."""
        reason = self.init_mismatch(path)
        if reason is None:
            self.load(path)
        elif required:
            raise UserError(f"{path}: {reason}")
        return reason

    def resume(self, path: str | Path) -> None:
        """Continue a run: weights, normalisers, optimisers, iteration/sample counters and the torch RNG."""
        data = self.load(path, load_optimizer=True)
        self.iteration = int(data["iteration"])
        self.total_samples = int(data.get("total_samples", 0))
        self.total_time_s = float(data.get("total_time_s", 0.0))
        rng = data.get("torch_rng_state")
        if isinstance(rng, Tensor):
            torch.set_rng_state(rng.cpu())
        best = self.log_dir / BEST_CHECKPOINT if self.log_dir is not None else None
        if best is not None and best.exists():  # later evaluations must beat the run's best, not start over
            self.best_eval = read_checkpoint(best).get("eval")

    def close(self) -> None:
        self.logger.close()

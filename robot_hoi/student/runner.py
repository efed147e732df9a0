"""Distillation with RL fine-tuning (InterMimic Alg. 1) on the PPO runner's hooks.

Each iteration (t = iterations done): the student executes its own sampled action with probability
min(t / beta, 1), the routed teacher's action otherwise (`_select_actions`); every transition stores the student's
sample (PPO.act) and the teacher's mean and std; the actor minimises w_PPO * L_PPO + w_D * L_distill
(PPO.surrogate_coef and PPO.extra_actor_loss) and the critic learns the env's (teacher) reward throughout.
Checkpoints, resume, TensorBoard and progress come from OnPolicyRunner; a student checkpoint is a PPO checkpoint
with policy_kind "student", the token layout and the task, plus the samplers' state for an exact resume.
With `data_parallel(rank)` it is one of several processes training one model (robot_hoi/student/distributed.py);
total_samples then counts every rank's samples, rank_samples this process's.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import torch
from torch import Tensor

from robot_hoi.errors import UserError
from robot_hoi.rl.checkpoint import load_model_state
from robot_hoi.rl.logger import LogWriter
from robot_hoi.rl.normalizer import RunningNormalizer
from robot_hoi.rl.ppo import PPO
from robot_hoi.rl.runner import OnPolicyRunner
from robot_hoi.student.config import StudentTrainConfig
from robot_hoi.student.distill import (
    kl_action_loss,
    l2_action_loss,
    loss_weights,
    mix_actions,
    student_probability,
)
from robot_hoi.student.distributed import GradientAverage, Rank, SyncedNormalizer, broadcast_state
from robot_hoi.student.model import StudentActorCritic
from robot_hoi.student.teachers import CompositeTeacher
from robot_hoi.student.tokens import TokenLayout

POLICY_KIND = "student"


class Stateful(Protocol):
    def state_dict(self) -> dict: ...

    def load_state_dict(self, state: dict) -> None: ...


class DistillationRunner(OnPolicyRunner):
    def __init__(self, env, cfg: StudentTrainConfig, teacher: CompositeTeacher, layout: TokenLayout,
                 log_dir: str | Path | None, device: str | torch.device = "cpu",
                 writers: list[LogWriter] | None = None, student_info: dict | None = None) -> None:
        super().__init__(env, cfg, log_dir, device, writers)
        if self.actor_dim != layout.obs_dim:
            raise UserError(f"student token layout covers {layout.obs_dim} observations, the actor groups "
                            f"{cfg.runner.actor_obs_groups} give {self.actor_dim}")
        num_actions = env.num_actions
        # the base runner built an MLP ActorCritic; the student replaces it (same interface for PPO and checkpoints)
        self.model = StudentActorCritic(layout, self.critic_dim, num_actions, cfg.student, cfg.model).to(self.device)
        self.alg = PPO(self.model, cfg.ppo, self.device)
        try:
            self.alg.init_storage(env.num_envs, self.actor_dim, self.critic_dim, num_actions,
                                  {"teacher_mean": num_actions, "teacher_std": num_actions})
        except ValueError as exc:
            raise UserError(str(exc)) from None
        self.alg.extra_actor_loss = self._distillation_loss
        self.teacher = teacher
        self.student_info = dict(student_info or {})
        self.stateful: dict[str, Stateful] = {}  # sampler states saved with each checkpoint
        self.iteration_hooks: list[Callable[[int], dict[str, float] | None]] = []
        self._student_probability = 1.0
        self._weights = (1.0, 0.0)
        self._hook_scalars: dict[str, float] = {}
        self.rank = Rank()
        self.rank_samples = 0  # samples this process collected (all ranks: total_samples)
        self.saved_checkpoints: list[Path] = []
        # the weight average (cfg.stability.ema_decay): made at the first update, after data_parallel has swapped
        # the normalisers; what is evaluated, selected and exported
        self.ema: StudentActorCritic | None = None
        self.ema_updates = 0
        if cfg.stability.lr_half_life > 0 and cfg.ppo.desired_kl is not None:
            raise UserError("stability.lr_half_life with ppo.desired_kl: the KL-adaptive rate would undo the decay; "
                            "use one (--set ppo.desired_kl=null)")
        self._reset_stats()

    def _reset_stats(self) -> None:
        self._executed_student = torch.zeros(())
        self._executed_total = 0
        self._distill_sum = 0.0
        self._distill_count = 0

    # --- data parallel (robot_hoi/student/distributed.py) --------------------------------------------------------
    def data_parallel(self, rank: Rank) -> None:
        """Train as `rank` of its process group: gradients and normaliser statistics shared with the other ranks,
        rank 0's parameters to start from, this rank's own action noise and DAgger draws."""
        self.rank = rank
        if not rank.distributed:
            return
        if self.cfg.ppo.desired_kl is not None:
            raise UserError("ppo.desired_kl (a KL-adaptive learning rate) with more than one process: each rank "
                            "would adapt its own rate from its own minibatches; use a fixed rate "
                            "(--set ppo.desired_kl=null, as the student presets do)")
        model = self.model
        if isinstance(model.actor_normalizer, RunningNormalizer):
            model.actor_normalizer = SyncedNormalizer.replacing(model.actor_normalizer)
            model.critic_normalizer = SyncedNormalizer.replacing(model.critic_normalizer)
        self.alg.gradient_hook = GradientAverage(rank.world_size)
        self._start_ranks_together()

    def _start_ranks_together(self) -> None:
        broadcast_state(self.model)
        torch.manual_seed(self.cfg.seed + 7919 * self.rank.rank + self.iteration)
        for obj in self.stateful.values():  # samplers restored from rank 0's checkpoint draw their own starts
            generator = getattr(obj, "generator", None)
            if isinstance(generator, torch.Generator) and not self.rank.is_main:
                generator.manual_seed(self.cfg.seed + 104729 * self.rank.rank + self.iteration)

    # --- Alg. 1 ------------------------------------------------------------------------------------------------
    def _on_iteration_start(self) -> None:
        t = self.iteration
        self._student_probability = student_probability(t, self.cfg.distill.beta)
        self._weights = loss_weights(t, self.cfg.distill)
        self.alg.surrogate_coef = self._weights[0]
        if self.cfg.stability.lr_half_life > 0:
            lr = self.cfg.ppo.actor_lr * self.cfg.stability.lr_scale(t)
            for group in self.alg.actor_optimizer.param_groups:
                group["lr"] = lr
        self._hook_scalars = {}
        for hook in self.iteration_hooks:
            self._hook_scalars.update(hook(t) or {})

    def _on_iteration_end(self) -> None:
        """Fold the updated weights into the average (parameters averaged, normaliser statistics taken as they are)."""
        if self.cfg.stability.ema_decay <= 0:
            return
        self.ema_updates += 1
        if self.ema is None:
            self.ema = copy.deepcopy(self.model).eval().requires_grad_(False)
            return
        decay = self.cfg.stability.ema_weight(self.ema_updates)
        with torch.no_grad():
            for average, current in zip(self.ema.parameters(), self.model.parameters(), strict=True):
                average.lerp_(current, 1.0 - decay)
            for average, current in zip(self.ema.buffers(), self.model.buffers(), strict=True):
                average.copy_(current)

    def evaluation_model(self) -> StudentActorCritic:
        return self.ema if self.ema is not None else self.model

    def _select_actions(self, actor_obs: Tensor, critic_obs: Tensor, extra_obs: dict[str, Tensor]) -> Tensor:
        """Alg. 1 lines 4-12: store the student's own sample a^(S) and the teacher's a^(T) with every transition;
        execute a^(S) with probability min(t / beta, 1), a^(T) otherwise. PPO's ratio is thus always taken on the
        student's own samples (on-policy): a teacher action can be very unlikely under the student, and its
        ratio after an update unbounded."""
        teacher_mean, teacher_std, _ = self.teacher.act(self.env)
        stored = {"teacher_mean": teacher_mean.to(self.device), "teacher_std": teacher_std.to(self.device)}
        student = self.alg.act(actor_obs, critic_obs, stored)
        n = actor_obs.shape[0]
        self._executed_total += n
        if self._student_probability >= 1.0:
            self._executed_student += n
            return student
        use_student = torch.rand(n, device=self.device) < self._student_probability
        self._executed_student += use_student.sum()
        return mix_actions(student, stored["teacher_mean"], use_student)

    def _distillation_loss(self, extra_obs: dict[str, Tensor], mean: Tensor) -> Tensor:
        teacher_mean = extra_obs["teacher_mean"]
        if self.cfg.distill.loss == "kl":
            raw = kl_action_loss(mean, self.model.action_std.expand_as(mean), teacher_mean,
                                 extra_obs["teacher_std"])
        else:
            raw = l2_action_loss(mean, teacher_mean)
        self._distill_sum += float(raw.detach())
        self._distill_count += 1
        return self._weights[1] * raw

    # --- logging -----------------------------------------------------------------------------------------------
    def _log(self, stats: dict[str, float], env_logs: dict[str, float], collection_s: float, learning_s: float):
        scalars = {
            "Distill/w_ppo": self._weights[0],
            "Distill/w_distill": self._weights[1],
            "Distill/student_probability": self._student_probability,
            "Distill/student_fraction": float(self._executed_student) / max(self._executed_total, 1),
            f"Distill/{'kl' if self.cfg.distill.loss == 'kl' else 'action_error'}":
                self._distill_sum / max(self._distill_count, 1),
            **self._hook_scalars,
        }
        self._reset_stats()
        batch = self.alg.storage.batch_size
        self.rank_samples += batch
        if self.rank.distributed:  # the loop counted this rank's batch; every rank collected one
            self.total_samples += batch * (self.rank.world_size - 1)
            scalars["Perf/ranks"] = float(self.rank.world_size)
            scalars["Perf/samples_per_s_all_ranks"] = self.rank.world_size * batch / max(collection_s + learning_s,
                                                                                         1e-9)
        return super()._log(stats, {**env_logs, **scalars}, collection_s, learning_s)

    # --- checkpoints ---------------------------------------------------------------------------------------------
    def save(self, path: str | Path, extra: dict[str, Any] | None = None) -> Path:
        """The runner's checkpoint contents (OnPolicyRunner.save) plus what only a student has."""
        self.saved_checkpoints.append(Path(path))
        return super().save(path, (extra or {}) | {
            "policy_kind": POLICY_KIND,
            "student": {**self.student_info, "token_layout": self.model.layout.to_dict()},
            "sampler_state": {name: obj.state_dict() for name, obj in self.stateful.items()},
            **({"ema_model": self.ema.state_dict(), "ema_updates": self.ema_updates} if self.ema is not None else {}),
        })

    def load(self, path: str | Path, load_optimizer: bool = False) -> dict[str, Any]:
        data = super().load(path, load_optimizer)
        if data.get("policy_kind") != POLICY_KIND:
            raise UserError(f"{path}: not a student checkpoint (policy_kind {data.get('policy_kind', 'teacher')!r})")
        self._loaded = data
        return data

    def resume(self, path: str | Path) -> None:
        super().resume(path)
        if "ema_model" in self._loaded and self.cfg.stability.ema_decay > 0:
            self.ema = copy.deepcopy(self.model).eval().requires_grad_(False)
            load_model_state(self.ema, self._loaded["ema_model"], path)
            self.ema_updates = int(self._loaded.get("ema_updates", self.iteration))
        states = self._loaded.get("sampler_state", {})
        for name, obj in self.stateful.items():
            if name in states:
                obj.load_state_dict(states[name])
        if self.rank.distributed:
            self._start_ranks_together()

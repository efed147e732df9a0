"""Teachers for distillation: load `robot-hoi train` runs and route every env to the teacher of its clip.

A teacher run folder holds one group per teacher (RUN_DIR/<group>/model_<it>.pt with task.json beside it), or is
itself one group. The composite teacher pi^(T) of InterMimic Alg. 1 maps env clip_id -> teacher; each teacher
reads its observation groups computed for its own clip against its own reference (reference_view.py), and its
action is re-expressed in the student env's action parametrisation (the same PD target), so executing or
imitating it means what the teacher meant.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch
from torch import Tensor

from robot_hoi.errors import UserError
from robot_hoi.rl.checkpoint import load_policy, policy_checkpoint
from robot_hoi.rl.config import TrainConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.sim.device import module_device
from robot_hoi.student.evaluation import evaluate_groups
from robot_hoi.student.reference_view import ReferenceView
from robot_hoi.student.student_env import ObservationProvider, StudentEnv

TASK_FILE = "task.json"
# Environment settings that change what a teacher's observation or action means. Teachers sharing one student
# env must agree on them (the rest, e.g. rewards or num_envs, may differ).
OBS_LAYOUT_KEYS = ("embodiment", "keyframes", "warmup_frames", "reference_links", "object_surface_points",
                   "action_clip", "action_offset")


@dataclass
class TeacherRun:
    """One trained teacher: its checkpoint, model and the task it was trained on."""

    name: str
    checkpoint: Path
    model: ActorCritic
    task: dict
    train_cfg: TrainConfig
    obs_groups: tuple[str, ...] = ("policy",)

    @property
    def sources(self) -> list[str]:
        return list(self.task["sources"])

    @property
    def env(self) -> dict:
        return self.task["env"]

    @property
    def action_offset(self) -> str:
        return self.env.get("action_offset", "default")  # tasks written before the option had absolute targets


def teacher_folders(run_dir: Path) -> list[Path]:
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserError(f"--teachers {run_dir}: no such folder (give the output folder of `robot-hoi train`)")
    if (run_dir / TASK_FILE).exists():
        return [run_dir]
    folders = sorted(p for p in run_dir.iterdir() if p.is_dir() and (p / TASK_FILE).exists())
    if not folders:
        raise UserError(f"--teachers {run_dir}: no teacher groups (folders with {TASK_FILE} and model_*.pt)")
    return folders


def load_teacher_runs(*run_dirs: str | Path) -> list[TeacherRun]:
    """The teachers of one or more `robot-hoi train` folders (a student of many skills takes several)."""
    runs = []
    folders = [f for run_dir in run_dirs for f in teacher_folders(Path(run_dir))]
    for folder in dict.fromkeys(folders):
        ckpt = policy_checkpoint(folder)
        if ckpt is None:
            raise UserError(f"{folder}: no model_*.pt checkpoint; train the teacher first")
        try:
            task = json.loads((folder / TASK_FILE).read_text())
        except json.JSONDecodeError as exc:
            raise UserError(f"{folder / TASK_FILE}: not valid JSON ({exc})") from None
        model, train_cfg, data = load_policy(ckpt)
        if data.get("policy_kind") == "student":
            raise UserError(f"{ckpt}: a student checkpoint, not a teacher")
        groups = tuple(data.get("obs_layout", {}).get("actor_groups", ["policy"]))
        runs.append(TeacherRun(folder.name, ckpt, model, task, train_cfg, groups))
    check_compatible(runs)
    return runs


def check_compatible(runs: list[TeacherRun]) -> None:
    """Teachers driving one student env must read the same observation layout and act the same way."""
    first = runs[0]
    for other in runs[1:]:
        differ = [k for k in OBS_LAYOUT_KEYS if first.env.get(k) != other.env.get(k)]
        if first.model.num_actor_obs != other.model.num_actor_obs and not differ:
            differ.append(f"observation size {first.model.num_actor_obs} vs {other.model.num_actor_obs}")
        if first.model.num_actions != other.model.num_actions:
            differ.append(f"action size {first.model.num_actions} vs {other.model.num_actions}")
        if differ:
            raise UserError(
                f"teachers {first.checkpoint} and {other.checkpoint} were trained with different task settings "
                f"({', '.join(differ)}); one student env cannot serve both: retrain them with matching settings "
                "or distil them separately")


@dataclass
class TeacherMember:
    """A teacher inside the composite: the model, how to build its input, and its action parametrisation."""

    name: str
    model: ActorCritic
    checkpoint: Path
    obs_groups: tuple[str, ...] = ("policy",)
    action_offset: str = "reference"  # the teacher env's env.action_offset
    extra_groups: dict[str, ObservationProvider] = field(default_factory=dict)  # e.g. an expert's "height_map"
    view: ReferenceView | None = None  # set once the student env exists

    def observation(self, cache: dict[tuple[int, str], Tensor]) -> Tensor:
        """The teacher's input for every env of the student env; `cache` shares groups between members."""
        parts = []
        for group in self.obs_groups:
            key = (id(self.view), group)
            if key not in cache:
                if group == "policy":
                    cache[key] = self.view.teacher_observation()
                elif group in self.extra_groups:
                    cache[key] = self.extra_groups[group](self.view, {}, None)
                else:
                    raise UserError(f"teacher {self.name}: observation group {group!r} is not available here")
            parts.append(cache[key])
        return parts[0] if len(parts) == 1 else torch.cat(parts, dim=-1)

    def own_env(self, env):
        """`env` (an InteractionEnv on the teacher's own reference) with the teacher's extra groups."""
        return StudentEnv(env, {g: self.extra_groups[g] for g in self.obs_groups if g != "policy"})

    def rollout_policy(self, wrapped_env) -> Callable[[dict[str, Tensor]], Tensor]:
        """Deterministic actions (on the env's device) from observation dicts of `own_env(...)`."""
        groups, device = list(self.obs_groups), module_device(self.model, wrapped_env.device)
        return lambda obs: self.model.act_inference(
            torch.cat([obs[g] for g in groups], dim=-1).to(device)).to(wrapped_env.device)

    def evaluate(self, env) -> dict[str, float]:
        """robot-hoi eval's metrics in `env` (its own reference, evaluation settings)."""
        return evaluate_groups(self.own_env(env), self.model, list(self.obs_groups))


class CompositeTeacher:
    """pi^(T): env -> (teacher action mean, teacher std, teacher index), each row from the teacher of its clip."""

    def __init__(self, members: list[TeacherMember], clip_teacher: list[int]) -> None:
        if not members:
            raise UserError("distillation needs at least one teacher")
        if min(clip_teacher) < 0 or max(clip_teacher) >= len(members):
            raise ValueError(f"clip -> teacher map {clip_teacher} names a teacher outside 0..{len(members) - 1}")
        self.members = members
        self.clip_teacher = torch.as_tensor(clip_teacher, dtype=torch.long)

    def route(self, clip_id: Tensor) -> Tensor:
        if self.clip_teacher.device != clip_id.device:
            self.clip_teacher = self.clip_teacher.to(clip_id.device)  # once: the index lives where the env is
        return self.clip_teacher[clip_id]

    @torch.no_grad()
    def act(self, env) -> tuple[Tensor, Tensor, Tensor]:
        """Teacher means and stds in the env's action parametrisation (on the env's device), and which teacher
        answered each row. One teacher answers every row without a host sync; several pick their rows."""
        which = self.route(env.clip_id)
        env_offset = env.action_offset()
        scale = env.action_scale
        cache: dict[tuple[int, str], Tensor] = {}
        if len(self.members) == 1:
            mean, std = self._answer(self.members[0], cache, env_offset, scale, None)
            return mean, std.expand(env.num_envs, -1), which
        mean = torch.zeros(env.num_envs, env.num_actions, device=env.device)
        std = torch.ones(env.num_envs, env.num_actions, device=env.device)
        for t, member in enumerate(self.members):
            rows = (which == t).nonzero().flatten()
            if rows.numel():
                mean[rows], std[rows] = self._answer(member, cache, env_offset[rows], scale, rows)
        return mean, std, which

    @staticmethod
    def _answer(member: TeacherMember, cache, env_offset: Tensor, scale: Tensor, rows: Tensor | None):
        """(mean, std) of `member` for `rows` (None: all), in the env's action parametrisation."""
        obs = member.observation(cache)
        obs = obs if rows is None else obs[rows]
        action = member.model.act_inference(obs.to(module_device(member.model, obs.device))).to(env_offset.device)
        offset = member.view.action_offset(member.action_offset)
        target = (offset if rows is None else offset[rows]) + scale * action
        std = member.model.action_std.to(env_offset.device).expand(action.shape[0], -1)
        return (target - env_offset) / scale, std


"""Evaluate a teacher checkpoint (or an untrained baseline) under an evaluation protocol and build the record
`robot-hoi eval` prints and writes, `robot-hoi compare` pools and `robot-hoi results` tabulates (a student's record
is built the same way by robot_hoi.student.eval_checkpoint)."""

from __future__ import annotations

import datetime
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from robot_hoi.embodiment import load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.paths import TASK_CONFIG
from robot_hoi.rl import evaluation
from robot_hoi.rl.checkpoint import load_policy, read_checkpoint, resolve_checkpoint
from robot_hoi.rl.config import PRESETS, load_train_config
from robot_hoi.rl.evaluation import EvalProtocol
from robot_hoi.rl.models import ActorCritic
from robot_hoi.rl.recipe import RECORD_FILE
from robot_hoi.sim.device import resolve_env_cfg
from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, saved_env_cfg
from robot_hoi.utils.config import load_yaml_dataclass

RECORD_SCHEMA = "robot-hoi.eval/1"


@dataclass
class EvalRequest:
    checkpoint: str                        # a checkpoint, a run or group folder, or "untrained"
    data: list[str] | None = None          # clips (None: the ones the checkpoint trained on)
    protocol: str = evaluation.DEFAULT_PROTOCOL
    episodes: int = evaluation.DEFAULT_EPISODES
    seed: int = evaluation.EVAL_SEED
    mass_scale: tuple[float, float] | None = None  # replaces the protocol's object_mass_scale
    overrides: list[str] = field(default_factory=list)  # env `--set` values
    embodiment: str = "g1_inspire"
    clip_options: dict[str, Any] | None = None     # from robot_hoi.data.cli_options.clip_options
    preset: str = "fast"                           # the network of "untrained"


def resolve_protocol(request: EvalRequest) -> tuple[str, EvalProtocol]:
    if request.episodes < 1:
        raise UserError(f"--episodes must be at least 1, got {request.episodes}")
    name, protocol = evaluation.load_protocol(request.protocol)
    if request.mass_scale is not None:
        lo, hi = request.mass_scale
        if not 0 < lo <= hi:
            raise UserError(f"--mass-scale must be 0 < LO <= HI, got {lo} {hi}")
        protocol.object_mass_scale = (lo, hi)
    return name, protocol


def evaluate_teacher(request: EvalRequest) -> dict[str, Any]:
    """The evaluation record of a teacher checkpoint (or of "untrained"): per clip and pooled, both success
    definitions. Students are evaluated by robot_hoi.student.eval_checkpoint into the same record."""
    name, protocol = resolve_protocol(request)
    ckpt = None
    if request.checkpoint != "untrained":
        ckpt = resolve_checkpoint(request.checkpoint)
    return make_record(request, name, protocol, "teacher" if ckpt else "untrained", ckpt,
                       _evaluate_teacher(request, protocol, ckpt))


def _evaluate_teacher(request: EvalRequest, protocol: EvalProtocol, ckpt: Path | None) -> dict[str, Any]:
    model = None
    task = None
    if ckpt is not None:
        model, _, _ = load_policy(ckpt)
        task = factory.read_task(ckpt) if request.data is None else None
    env_cfg = saved_env_cfg(task["env"], f"{ckpt} task") if task else \
        load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)
    sources = task["sources"] if task else factory.expand_sources(request.data)
    options = {**(task.get("clip_options") or {}), **(request.clip_options or {})} if task else \
        (request.clip_options or {})
    embodiment = load_embodiment(request.embodiment)
    evaluation.evaluation_settings(env_cfg, request.episodes, request.seed, protocol)
    env_cfg = evaluation.apply_env_overrides(env_cfg, request.overrides)  # after: `--set` may change the protocol
    env_cfg = resolve_env_cfg(env_cfg)  # once: every clip's env on the same device, the model moved there

    clips = {}
    for source in sources:
        clip = factory.load_source(source, options or None)
        cache = ckpt.parent / "references" if ckpt is not None and (ckpt.parent / "references").is_dir() else None
        env = factory.make_env([clip], env_cfg, embodiment, cache=cache)
        if model is None:
            torch.manual_seed(request.seed)
            train_cfg = load_train_config(PRESETS[request.preset])
            model = ActorCritic(env.obs_dims["policy"], env.obs_dims["critic"], env.num_actions, train_cfg.model)
            model.eval()
        clips[clip.name] = evaluation.clip_record(
            evaluation.evaluate_definitions(env, model.to(env.device), request.seed))
    return clips


def make_record(request: EvalRequest, name: str, protocol: EvalProtocol, kind: str, ckpt: Path | None,
            clips: dict[str, Any]) -> dict[str, Any]:
    record: dict[str, Any] = {
        "schema": RECORD_SCHEMA,
        "kind": kind,
        "checkpoint": str(ckpt or request.checkpoint),
        **_training_facts(ckpt),
        "protocol": evaluation.protocol_record(name, protocol, request.episodes, request.seed),
        "clips": clips,
        "overall": evaluation.overall_record(clips),
        "evaluated": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip() + f", {_cpu_count()} CPUs",
    }
    return record


def _training_facts(ckpt: Path | None) -> dict[str, Any]:
    """What the checkpoint says of its training: iteration, samples, training time, the run's recipe."""
    if ckpt is None:
        return {}
    data = read_checkpoint(ckpt)
    facts = {"iteration": int(data.get("iteration", 0)), "samples": int(data.get("total_samples", 0)),
             "train_time_s": round(float(data.get("total_time_s", 0.0)), 1)}
    # the run folder (above the group folders) records the recipe it trained with
    recipe = next((folder / RECORD_FILE for folder in (ckpt.parent, ckpt.parent.parent)
                   if (folder / RECORD_FILE).is_file()), None)
    if recipe is not None:
        facts["recipe_file"] = str(recipe)
    return facts


def _cpu_count() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)

"""ComplexMimic Stage I (Sec. 3.1) and the regime routing (Eq. 2), per teacher group.

- imitation expert: tracks strictly, early termination at tau = 0.25 m mean link error;
- interaction expert: relaxed tau = 0.5 m, and sees a 20 x 20 heading-aligned height map (8 cm) of the scene.
Both start from the group's teacher (the interaction expert's height-map inputs zero-initialised, so it starts as
the teacher) and are fine-tuned with PPO for their share of the budget; `interaction_init: scratch` trains it
from a fresh network instead. Each lives in OUT/experts/<group>/<kind>/ as a normal teacher run and is reused
when its checkpoint exists.
Routing: each clip goes to the imitation expert if that expert tracks it successfully (success rate >=
routing_success over routing_episodes evaluation episodes, failure = the 0.5 m criterion), else to the
interaction expert.
"""

from __future__ import annotations

import copy
import json

import torch

from deploy.atomic import atomic_write_text
from robot_hoi.rl.checkpoint import policy_checkpoint
from robot_hoi.rl.runner import OnPolicyRunner
from robot_hoi.student.height_map import HeightMap
from robot_hoi.student.student_env import StudentEnv
from robot_hoi.student.task import evaluation_cfg
from robot_hoi.student.teachers import TeacherMember, TeacherRun
from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env import InteractionEnv

IMITATE, INTERACT = 0, 1
KINDS = ("imitation", "interaction")


def route_by_success(success_rates: list[float], threshold: float) -> list[int]:
    """Eq. 2: G_Imitate (0) where the imitation expert succeeds, G_Inter (1) elsewhere."""
    return [IMITATE if rate >= threshold else INTERACT for rate in success_rates]


def expand_inputs(state: dict, prefix: str, extra: int, extra_mean: torch.Tensor, extra_var: torch.Tensor) -> dict:
    """A network state for `extra` more inputs: zero weight columns for them (the output is unchanged) and
    normaliser statistics from a first batch of them."""
    state = dict(state)
    weight = state[f"{prefix}.0.weight"]
    state[f"{prefix}.0.weight"] = torch.cat([weight, weight.new_zeros(weight.shape[0], extra)], dim=1)
    norm = f"{prefix}_normalizer"
    if f"{norm}.mean" in state:
        mean = state[f"{norm}.mean"]
        state[f"{norm}.mean"] = torch.cat([mean, extra_mean.to(mean.device)])
        state[f"{norm}.var"] = torch.cat([state[f"{norm}.var"], extra_var.to(mean.device)])
    return state


def train_expert(setup, run: TeacherRun, clip_ids: list[int], kind: str, budget, height_map: HeightMap
                 ) -> TeacherMember:
    cm = setup.cfg.complexmimic
    folder = setup.out / "experts" / run.name / kind
    folder.mkdir(parents=True, exist_ok=True)
    env_cfg = copy.deepcopy(setup.teacher_env_cfg)
    env_cfg.terminations.max_mean_link_error = cm.imitation_tau if kind == "imitation" else cm.interaction_tau
    env = InteractionEnv(env_cfg, setup.scene, [setup.mocap[i] for i in clip_ids])
    train_cfg = copy.deepcopy(run.train_cfg)
    train_cfg.runner.progress = setup.cfg.runner.progress
    train_cfg.runner.tensorboard = setup.cfg.runner.tensorboard
    providers = {}
    if kind == "interaction":
        providers = {"height_map": height_map}
        train_cfg.runner.actor_obs_groups = [*run.train_cfg.runner.actor_obs_groups, "height_map"]
        train_cfg.runner.critic_obs_groups = [*run.train_cfg.runner.critic_obs_groups, "height_map"]
    wrapped = StudentEnv(env, providers)
    existing = policy_checkpoint(folder)
    if existing is not None:  # loaded without a log folder: reusing an expert writes nothing
        runner = OnPolicyRunner(wrapped, train_cfg, None, device=setup.device)
        runner.load(existing)
        print(f"[complexmimic] {run.name} {kind} expert from {existing}")
    else:
        factory.write_task(folder, [setup.sources[i] for i in clip_ids], env_cfg, setup.embodiment.name,
                           f"{run.name}-{kind}")
        runner = OnPolicyRunner(wrapped, train_cfg, folder, device=setup.device)
        if kind == "imitation":
            runner.model.load_state_dict(run.model.state_dict())
        elif cm.interaction_init == "teacher":
            first = height_map(env)
            mean, var = first.mean(0), first.var(0, unbiased=False).clamp(min=1e-2)
            state = expand_inputs(run.model.state_dict(), "actor", height_map.dim, mean, var)
            state = expand_inputs(state, "critic", height_map.dim, mean, var)
            runner.model.load_state_dict(state)
        print(f"[complexmimic] fine-tuning the {kind} expert of {run.name} "
              f"(tau {env_cfg.terminations.max_mean_link_error}, budget {budget.describe()})")
        runner.learn(budget)
        existing = policy_checkpoint(folder)
    runner.close()
    return TeacherMember(f"{run.name}/{kind}", runner.model.eval(), existing,
                         tuple(train_cfg.runner.actor_obs_groups), run.action_offset,
                         {"height_map": height_map} if kind == "interaction" else {})


def prepare_experts(setup, budget, resume: bool = False, write: bool = True) -> None:
    """Replace setup.members by two experts per teacher and route every clip (setup.clip_teacher/clip_group).
    Experts already in OUT/experts are reused; `write` False leaves routing.json alone (ranks other than 0)."""
    cm = setup.cfg.complexmimic
    height_map = HeightMap(setup.scene.object_asset, cm.height_map_size, cm.height_map_spacing)
    share = budget.scaled(1.0 / (2 * len(setup.runs)))
    members, clip_teacher, clip_group, routing = [], list(setup.clip_teacher), [0] * len(setup.sources), {}
    eval_cfg = evaluation_cfg(setup.teacher_env_cfg, cm.routing_episodes)
    eval_cfg.terminations.max_mean_link_error = cm.student_tau  # success: never 0.5 m off (ComplexMimic Sec. 4.1)
    for g, run in enumerate(setup.runs):
        clip_ids = [i for i, t in enumerate(setup.clip_teacher) if t == g]
        experts = [train_expert(setup, run, clip_ids, kind, share, height_map) for kind in KINDS]
        base = len(members)
        members += experts
        rates = [experts[IMITATE].evaluate(InteractionEnv(eval_cfg, setup.scene, [setup.mocap[i]]))["success_rate"]
                 for i in clip_ids]
        for i, rate, group in zip(clip_ids, rates, route_by_success(rates, cm.routing_success), strict=True):
            clip_teacher[i], clip_group[i] = base + group, group
            routing[setup.clips[i].name] = {"teacher": run.name, "imitation_success": rate,
                                            "group": KINDS[group], "expert": experts[group].name}
    setup.members, setup.clip_teacher, setup.clip_group = members, clip_teacher, clip_group
    setup.task_extra["routing"] = routing
    if write:
        atomic_write_text(setup.out / "routing.json", json.dumps(routing, indent=2) + "\n")
    for clip, info in routing.items():
        print(f"[complexmimic] {clip}: imitation expert success {info['imitation_success']:.2f} -> {info['expert']}")

"""`robot-hoi train student`: teachers -> (options) -> distilled references -> student env -> Alg. 1 -> evaluation.

    robot-hoi train --budget 2h --out runs/teachers                       # teachers (one per subject-object group)
    robot-hoi train student --teachers runs/teachers --budget 1h --out runs/student
    robot-hoi train student --teachers runs/teachers --option complexmimic --set complexmimic.update_every=20
    robot-hoi train student --teachers runs/teachers --option skillmimic_deployable --resume
    robot-hoi export onnx runs/student/student/model_<it>.pt -o policies/student.onnx
    robot-hoi train student --teachers runs/teachers --device cuda --budget 1h   # one rank per CUDA device

With several ranks (robot_hoi/student/launch.py, distributed.py) every rank runs `train` with its own envs; rank 0
alone writes, the others only compute.

Run folder OUT/: student/ (checkpoints, task.json, TensorBoard, scalars.jsonl, eval.json), references/ (distilled
references, reused on --resume), and with ComplexMimic experts/<group>/{imitation,interaction}/ and routing.json,
with SkillMimic-V2 history_encoder.pt. The student env is the teachers' env config (they must agree on it) with
the deployable observation switched on; `--set env.*` changes it, other `--set` keys the student config.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

from deploy.atomic import atomic_write_text
from robot_hoi.data.cli_options import clip_options
from robot_hoi.embodiment import load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.rl.budget import Budget, parse_budget
from robot_hoi.rl.checkpoint import latest_checkpoint
from robot_hoi.rl.eval_curve import EVAL_CURVE_FILE, read_curve
from robot_hoi.rl.evaluation import (
    DEFAULT_PROTOCOL,
    VALIDATION_SEED,
    selection_env_cfg,
    summarise,
    validation_label,
)
from robot_hoi.sim.device import physics_device, resolve_env_cfg
from robot_hoi.student import complexmimic, skillmimic
from robot_hoi.student.config import DEFAULT_PRESET, PRESETS, StudentTrainConfig, load_student_config
from robot_hoi.student.distributed import Rank, SharedBudget, state_checksum, sum_over_ranks
from robot_hoi.student.evaluation import evaluate_groups, format_table
from robot_hoi.student.experts import prepare_experts
from robot_hoi.student.object_groups import GroupedTeacher, ObjectGroupsEnv, split_envs
from robot_hoi.student.reference_distill import FORMAT as REFERENCE_FORMAT
from robot_hoi.student.reference_distill import load_reference, rollout_reference, save_reference
from robot_hoi.student.reference_view import ReferenceTimeline, ReferenceView
from robot_hoi.student.runner import DistillationRunner
from robot_hoi.student.student_env import StudentEnv, fresh_providers
from robot_hoi.student.task import (
    STUDENT_GROUP,
    evaluation_cfg,
    mocap_reference,
    object_scenes,
    student_env_cfg,
    write_student_task,
)
from robot_hoi.student.teachers import CompositeTeacher, TeacherMember, TeacherRun, load_teacher_runs
from robot_hoi.student.tokens import token_layout
from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, saved_env_cfg
from robot_hoi.tasks.interaction.mdp.observations import student_observation_spec
from robot_hoi.utils.config import apply_overrides


@dataclass
class Setup:
    """Everything the student run is assembled from (filled step by step)."""

    cfg: StudentTrainConfig
    env_cfg: InteractionEnvCfg  # the student env's config
    teacher_env_cfg: InteractionEnvCfg  # the teachers' (shared) env config
    embodiment: object
    runs: list[TeacherRun]
    sources: list[str]
    clips: list
    mocap: list  # MoCap ReferenceMotion per clip
    scenes: list  # the scene of each clip's object (clips of one object share it)
    out: Path
    device: str = "cpu"
    members: list[TeacherMember] = field(default_factory=list)
    clip_teacher: list[int] = field(default_factory=list)
    clip_group: list[int] = field(default_factory=list)  # ComplexMimic regime per clip (0 imitate, 1 interact)
    task_extra: dict = field(default_factory=dict)

    @property
    def scene(self):
        """The one scene of a single-object run (what the single-object options build on)."""
        if len({id(s) for s in self.scenes}) > 1:
            raise UserError(f"this needs the clips of one object; the teachers' clips use "
                            f"{sorted({c.object_name for c in self.clips})}")
        return self.scenes[0]

    def object_groups(self, clips: list[int]) -> list[list[int]]:
        """`clips` grouped by object, groups in order of first appearance."""
        groups: dict[int, list[int]] = {}
        for i in clips:
            groups.setdefault(id(self.scenes[i]), []).append(i)
        return list(groups.values())


def prepare(args: argparse.Namespace) -> Setup:
    if not getattr(args, "teachers", None):
        raise UserError("robot-hoi train student needs --teachers RUN_DIR (the output folder of `robot-hoi train`)")
    if getattr(args, "data", None):
        raise UserError("robot-hoi train student: --data does not apply; the student learns its teachers' clips")
    config_path = args.config or PRESETS[args.preset or DEFAULT_PRESET]  # None: no --preset (nor recipe)
    cfg, env_overrides = load_student_config(config_path, getattr(args, "options", []), args.overrides)
    runs = load_teacher_runs(*args.teachers)
    teacher_env_cfg = saved_env_cfg(runs[0].env, f"{runs[0].checkpoint.parent}/task.json")
    teacher_env_cfg = apply_overrides(teacher_env_cfg, [o for o in env_overrides if o.startswith("num_envs=")
                                                        or o.startswith("nthread=")], "--set env.*")
    env_cfg = student_env_cfg(apply_overrides(saved_env_cfg(runs[0].env, "teacher task"),
                                              env_overrides, "--set env.*"))
    if cfg.complexmimic.enabled:
        env_cfg.terminations.max_mean_link_error = cfg.complexmimic.student_tau
    # The physics chosen once for every env of this process (student, teacher rollouts, experts, evaluation; a
    # data-parallel rank: its own GPU); the teachers act on those envs' observations, so they move there.
    env_cfg = resolve_env_cfg(env_cfg)
    teacher_env_cfg.backend, teacher_env_cfg.sim_device = env_cfg.backend, env_cfg.sim_device
    for run in runs:
        run.model.to(physics_device(env_cfg))
    embodiment = load_embodiment(env_cfg.embodiment)
    sources: list[str] = []
    clip_teacher: list[int] = []
    for index, run in enumerate(runs):
        for source in run.sources:
            if source not in sources:  # a clip two teachers trained on goes to the first
                sources.append(source)
                clip_teacher.append(index)
    options = clip_options(args, runs[0].task.get("clip_options"))
    clips = [factory.load_source(s, options) for s in sources]
    scenes = object_scenes(clips, embodiment, env_cfg)
    source_run = {s: runs[clip_teacher[i]] for i, s in enumerate(sources)}
    mocap = [mocap_reference(c, embodiment, teacher_env_cfg, source_run[s].checkpoint.parent / "references")
             for c, s in zip(clips, sources, strict=True)]
    out = Path(args.out) if args.out else Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-student"
    members = [TeacherMember(run.name, run.model, run.checkpoint, run.obs_groups, run.action_offset) for run in runs]
    if len(scenes) > 1 and (cfg.complexmimic.enabled or cfg.skillmimic.enabled):
        raise UserError(f"the ComplexMimic and SkillMimic-V2 options need the clips of one object; the teachers' "
                        f"clips use {sorted(scenes)}: distil one student per object with them")
    return Setup(cfg, env_cfg, teacher_env_cfg, embodiment, runs, sources, clips, mocap,
                 [scenes[c.object_name] for c in clips], out, args.device, members, clip_teacher,
                 [0] * len(sources), {"clip_options": options})


def rollout_env(setup: Setup, index: int, cfg: InteractionEnvCfg | None = None):
    """One env (num_envs 1, eval settings) on clip `index`'s MoCap reference, long enough for the whole clip."""
    cfg = evaluation_cfg(cfg or setup.teacher_env_cfg, num_envs=1)
    cfg.max_episode_frames = max(cfg.max_episode_frames, setup.mocap[index].num_frames + cfg.warmup_frames + 2)
    return InteractionEnv(cfg, setup.scenes[index], [setup.mocap[index]])


def distil_references(setup: Setup) -> list[tuple[object, str | None]]:
    """(reference, path relative to OUT/student) per clip: the routed teacher's rollout (None: clip dropped)."""
    folder = setup.out / "references"
    d = setup.cfg.distill
    results: list[tuple[object, str | None]] = []
    for i, (clip, source) in enumerate(zip(setup.clips, setup.sources, strict=True)):
        member = setup.members[setup.clip_teacher[i]]
        path = folder / f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', clip.name)}.npz"
        identity = {"format": REFERENCE_FORMAT, "source": source, "teacher": member.name,
                    "checkpoint": str(member.checkpoint),
                    "checkpoint_mtime": member.checkpoint.stat().st_mtime, "min_frames": d.reference_min_frames,
                    "failure_margin": d.reference_failure_margin}
        if path.exists():
            reference, meta = load_reference(path)
            if {k: meta.get(k) for k in identity} == identity:
                results.append((reference, f"../references/{path.name}"))
                print(f"[reference] {clip.name}: reusing {path}")
                continue
        env = member.own_env(rollout_env(setup, i))
        outcome = rollout_reference(env, member.rollout_policy(env), d.reference_min_frames,
                                    d.reference_failure_margin)
        print(f"[reference] {clip.name} by {member.name}: {outcome.describe()}")
        if outcome.reference is None:
            results.append((None, None))
            continue
        save_reference(outcome.reference, path, {**identity, "frames_reached": outcome.frames_reached,
                                                 "terminated": outcome.terminated})
        results.append((outcome.reference, f"../references/{path.name}"))
    return results


@dataclass
class StudentParts:
    """The student env and what the runner is built from."""

    student_env: object  # StudentEnv
    composite: CompositeTeacher
    layout: object  # TokenLayout
    spec: list[dict]
    keep: list[int]  # indices of the clips kept (a dropped clip had no usable teacher rollout)
    options: list = field(default_factory=list)  # option setups, attached to the runner once it exists


def student_environment(setup: Setup, write: bool = True) -> StudentParts:
    """The student env (with the options' providers): distils (or reuses) the references, pre-trains (or loads) the
    SkillMimic-V2 history encoder and, with `write`, records the task in OUT/student/task.json."""
    cfg = setup.cfg
    if cfg.distill.reference == "teacher":
        distilled = distil_references(setup)
    else:
        distilled = [(m, None) for m in setup.mocap]
    kept = [i for i, (ref, _) in enumerate(distilled) if ref is not None]
    if not kept:
        raise UserError("no teacher rollout tracked its clip long enough to serve as a reference "
                        f"(distill.reference_min_frames = {cfg.distill.reference_min_frames}); train the teachers "
                        "longer, or use --set distill.reference=mocap")
    groups = setup.object_groups(kept)
    keep = [i for group in groups for i in group]  # the env numbers clips group by group
    for a, b in itertools.combinations(groups, 2):
        shared = {setup.clip_teacher[i] for i in a} & {setup.clip_teacher[i] for i in b}
        if shared:
            raise UserError(f"teacher {setup.members[min(shared)].name} has clips of two objects; train one teacher "
                            "per object (robot-hoi train --group object)")
    if len(groups) == 1:
        env, composite = object_group(setup, groups[0], setup.env_cfg, distilled)
    else:
        counts = split_envs(setup.env_cfg.num_envs, [len(g) for g in groups])
        cfgs = [dataclasses.replace(setup.env_cfg, num_envs=n, seed=setup.env_cfg.seed + k)
                for k, n in enumerate(counts)]
        parts = [object_group(setup, g, c, distilled) for g, c in zip(groups, cfgs, strict=True)]
        env, composite = ObjectGroupsEnv([p[0] for p in parts]), GroupedTeacher([p[1] for p in parts])
        print(f"[student] {len(groups)} objects, one env each: " + ", ".join(
            f"{setup.clips[g[0]].object_name} ({len(g)} clip(s), {n} envs)" for g, n in zip(groups, counts,
                                                                                        strict=True)))

    providers, spec_extra = {}, []
    options = []
    if cfg.skillmimic.enabled:
        options.append(skillmimic.SkillMimicSetup(cfg.skillmimic, env, setup.out, cfg.seed))
        providers.update(options[-1].providers())
        spec_extra += options[-1].spec_extra()
    student_env = StudentEnv(env, providers)
    spec = student_observation_spec(env.envs[0] if isinstance(env, ObjectGroupsEnv) else env) + spec_extra
    layout = token_layout(spec, setup.env_cfg.student_keyframes)
    cfg.runner.actor_obs_groups = ["student", *providers]
    if write:
        folder = setup.out / STUDENT_GROUP
        folder.mkdir(parents=True, exist_ok=True)
        task_extra = {**setup.task_extra, "teachers": [str(r.checkpoint) for r in setup.runs],
                      "clip_teacher": [setup.members[setup.clip_teacher[i]].name for i in keep],
                      "dropped_clips": [setup.sources[i] for i in range(len(setup.sources)) if i not in keep]}
        write_student_task(folder, sources=[setup.sources[i] for i in keep],
                           references=[distilled[i][1] for i in keep], env_cfg=setup.env_cfg,
                           embodiment_name=setup.embodiment.name, extra=task_extra)
    return StudentParts(student_env, composite, layout, spec, keep, options)


def object_group(setup: Setup, clips: list[int], env_cfg: InteractionEnvCfg, distilled):
    """The env of one object's `clips` (on their distilled references) and the composite of their teachers, each
    teacher reading its observation against that env (its own ReferenceView)."""
    env = InteractionEnv(env_cfg, setup.scenes[clips[0]], [distilled[i][0] for i in clips])
    timeline = ReferenceTimeline([setup.mocap[i] for i in clips], env)
    view = ReferenceView(env, timeline, setup.teacher_env_cfg.keyframes, setup.teacher_env_cfg.warmup_frames,
                         setup.teacher_env_cfg.teacher_obs, setup.teacher_env_cfg.action_offset)
    teachers = sorted({setup.clip_teacher[i] for i in clips})
    for t in teachers:
        setup.members[t].view = view
    return env, CompositeTeacher([setup.members[t] for t in teachers],
                                 [teachers.index(setup.clip_teacher[i]) for i in clips])


def build_student(setup: Setup, args: argparse.Namespace, rank: Rank | None = None):
    """The student env (with the options' providers and samplers) and its DistillationRunner, as `rank` of a
    data-parallel group (default: a single process). Only rank 0 logs and writes."""
    rank = rank or Rank()
    cfg = setup.cfg
    parts = student_environment(setup, write=rank.is_main)
    if not rank.is_main:
        cfg.runner.progress = False
    sources = [setup.sources[i] for i in parts.keep]
    torch.manual_seed(cfg.seed)
    runner = DistillationRunner(parts.student_env, cfg, parts.composite, parts.layout,
                                setup.out / STUDENT_GROUP if rank.is_main else None, device=setup.device,
                                student_info={"obs_spec": parts.spec, "sources": sources,
                                              "keyframes": list(setup.env_cfg.student_keyframes)})
    options = list(parts.options)
    if cfg.complexmimic.enabled and cfg.complexmimic.sampling:
        reduce = sum_over_ranks(rank.device) if rank.distributed else None  # every rank's episodes
        options.append(complexmimic.DifficultySetup(cfg.complexmimic, [setup.clip_group[i] for i in parts.keep],
                                                    cfg.seed, reduce=reduce))
    for option in options:
        option.attach(runner, parts.student_env)
    runner.data_parallel(rank)
    return runner, parts.student_env, parts.keep


def prepare_run(args: argparse.Namespace, rank: Rank | None = None) -> tuple[Setup, Budget]:
    """Teachers, config and (ComplexMimic) experts; the student's share of the budget."""
    rank = rank or Rank()
    setup = prepare(args)
    if rank.distributed:
        setup.device = rank.device
        setup.env_cfg.seed += rank.rank  # each rank its own envs
        if setup.env_cfg.nthread is None:  # the ranks share the cores
            setup.env_cfg.nthread = max(1, (os.cpu_count() or 1) // rank.world_size)
    budget = parse_budget(args.budget)
    if rank.is_main:
        print(f"student from {len(setup.runs)} teacher(s) on {len(setup.clips)} clip(s) -> {setup.out}")
    if setup.cfg.complexmimic.enabled:
        expert_budget = budget.scaled(setup.cfg.complexmimic.expert_budget_fraction)
        budget = budget.scaled(1.0 - setup.cfg.complexmimic.expert_budget_fraction)
        prepare_experts(setup, expert_budget, resume=args.resume, write=rank.is_main)
    return setup, budget


def train(args: argparse.Namespace, rank: Rank | None = None) -> dict:
    """Train the student in this process (as `rank` of a data-parallel group, or alone); rank 0 evaluates it.
    Returns this rank's report: samples it collected, the run's total, its parameter checksum, what it saved."""
    rank = rank or Rank()
    setup, budget = prepare_run(args, rank)
    runner, student_env, keep = build_student(setup, args, rank)
    folder = setup.out / STUDENT_GROUP
    if args.resume:
        latest = latest_checkpoint(folder)
        if latest is not None:
            runner.resume(latest)
            if rank.is_main:
                print(f"[student] resumed from {latest} (iteration {runner.iteration})")
    if rank.is_main and setup.cfg.runner.eval_interval:
        runner.evaluator = validation_evaluator(setup, runner, keep)
        runner.on_evaluation = lambda row: print(
            f"[student] validation at it {row['step']}: success {row['success_rate']:.2f}, interaction "
            f"{row['interaction_success_rate']:.2f}, E_h {row['E_h_cm']:.1f} cm"
            f"{' (best so far: model_best.pt)' if row['best'] else ''}")
    if rank.is_main:
        ranks = f" x {rank.world_size} ranks" if rank.distributed else ""
        print(f"[student] obs {student_env.obs_dims}, {student_env.num_envs} envs{ranks}, "
              f"{sum(p.numel() for p in runner.model.actor.parameters()):,} actor parameters")
    stats = runner.learn(SharedBudget(budget, rank.world_size, rank.device) if rank.distributed else budget)
    rank.wait_for_all()  # the last collective is behind every rank; rank 0's evaluation needs none
    runner.close()
    student_env.close()  # its physics threads stop now (the runner lives on in a reference cycle)
    report = {"rank": rank.rank, "world_size": rank.world_size, "samples": runner.rank_samples,
              "total_samples": runner.total_samples, "iteration": runner.iteration,
              "checksum": state_checksum(runner.model), "checkpoints": [str(p) for p in runner.saved_checkpoints]}
    if not rank.is_main:
        return report
    print(f"[student] {({k: round(v, 3) for k, v in stats.items()})}")
    selection = selection_record(folder, setup.cfg)
    if selection is not None:
        atomic_write_text(folder / SELECTION_FILE, json.dumps(selection, indent=2) + "\n")
        print(f"[student] selected {selection['checkpoint']} (iteration {selection['iteration']}, validation "
              f"success {selection['best']['success_rate']:.2f}; its neighbours within "
              f"{selection['neighbour_success_spread']:.2f}): {folder / SELECTION_FILE}")
    if setup.cfg.eval_episodes > 0:
        evaluation = evaluate_run(setup, runner, keep)
        atomic_write_text(folder / "eval.json", json.dumps(evaluation, indent=2) + "\n")
    print(f"done: {folder}")
    return report


def evaluate_run(setup: Setup, runner, keep: list[int]) -> dict:
    """Each kept clip: the teacher on MoCap, the student on its reference and on MoCap (what a deploy tracks)."""
    episodes = setup.cfg.eval_episodes
    rows: dict[str, dict[str, dict[str, float]]] = {}
    model = runner.evaluation_model().eval()
    env_refs = runner.env.env.references
    for k, i in enumerate(keep):
        clip = setup.clips[i]
        member = setup.members[setup.clip_teacher[i]]
        teacher_env = InteractionEnv(evaluation_cfg(setup.teacher_env_cfg, episodes), setup.scenes[i],
                                     [setup.mocap[i]])
        rows.setdefault(f"teacher {member.name} (MoCap)", {})[clip.name] = member.evaluate(teacher_env)
        for label, reference in (("student (its reference)", env_refs[k]), ("student (MoCap)", setup.mocap[i])):
            env = InteractionEnv(evaluation_cfg(setup.env_cfg, episodes), setup.scenes[i], [reference])
            wrapped = StudentEnv(env, fresh_providers(runner.env.providers, episodes))
            rows.setdefault(label, {})[clip.name] = evaluate_groups(wrapped, model, runner.cfg.runner.actor_obs_groups)
    for line in format_table(rows):
        print(line)
    return rows


SELECTION_FILE = "selection.json"


def validation_evaluator(setup: Setup, runner, keep: list[int]):
    """model -> mean metrics over the kept clips, each on the reference it trained on (the one its export deploys
    with), under the randomized protocol on validation seeds (VALIDATION_SEED + seed, disjoint from `robot-hoi
    eval`'s) as the teachers' model selection: envs built once and re-seeded, so every checkpoint meets the same
    starts. The runner keeps the best as model_best.pt."""
    seed = VALIDATION_SEED + setup.cfg.seed
    episodes = setup.cfg.runner.eval_episodes
    envs = {}
    for k, i in enumerate(keep):
        env = InteractionEnv(selection_env_cfg(setup.env_cfg, episodes, seed), setup.scenes[i],
                             [runner.env.env.references[k]])
        envs[setup.clips[i].name] = StudentEnv(env, fresh_providers(runner.env.providers, episodes))
    groups = runner.cfg.runner.actor_obs_groups

    def evaluator(model) -> dict[str, float]:
        results = {}
        for name, env in envs.items():
            env.env.generator.manual_seed(seed)
            results[name] = evaluate_groups(env, model, groups)
        return {**summarise(results), **validation_label(setup.env_cfg)}

    return evaluator


def selection_record(folder: Path, cfg: StudentTrainConfig) -> dict | None:
    """Which checkpoint the run stands for (model_best.pt) and the evidence: its validation row, the evaluations
    before and after it and how far their success spreads, the protocol and the stability settings. None without
    in-training evaluations."""
    path = folder / EVAL_CURVE_FILE
    if not path.is_file():
        return None
    rows = list({row["step"]: row for row in read_curve(path)}.values())  # a resumed run re-evaluates: keep the last
    rows.sort(key=lambda row: row["step"])
    best = [i for i, row in enumerate(rows) if row.get("best")]
    if not best:
        return None
    i = best[-1]
    around = rows[max(i - 1, 0): i + 2]
    successes = [row["success_rate"] for row in around]
    return {
        "checkpoint": "model_best.pt",
        "iteration": rows[i]["step"],
        "rule": "the best validation evaluation (eval_curve.eval_rank: success, interaction success, tracked "
                "duration)",
        "validation": {"protocol": DEFAULT_PROTOCOL, "seed": VALIDATION_SEED + cfg.seed,
                       "randomization": rows[i].get("validation", "none (the protocol's starts only)"),
                       "episodes_per_clip": cfg.runner.eval_episodes, "every_iterations": cfg.runner.eval_interval},
        "weights": (f"exponential moving average, decay {cfg.stability.ema_decay}" if cfg.stability.ema_decay > 0
                    else "the trained weights (no average)"),
        "actor_lr": ({"half_life_iterations": cfg.stability.lr_half_life, "floor": cfg.stability.lr_floor}
                     if cfg.stability.lr_half_life > 0 else "constant"),
        "best": rows[i],
        "neighbours": [row for row in around if row is not rows[i]],
        "neighbour_success_spread": max(successes) - min(successes),
        "evaluations": len(rows),
    }

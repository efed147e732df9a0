"""`robot-hoi train`: InterMimic teachers (one per group) on the embodiment, from clips or the embedded default."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from robot_hoi.data.cli_options import add_clip_options, clip_options
from robot_hoi.paths import TASK_CONFIG
from robot_hoi.rl.config import PRESETS
from robot_hoi.rl.recipe import FLAGS, RECORD_FILE, recipe_names
from robot_hoi.tasks.interaction.env_cfg import reward_set_names

SUMMARY_FILE = "teachers.json"  # per-teacher summaries of the last `robot-hoi train` into this run folder
DEFAULT_BUDGET, DEFAULT_PRESET, DEFAULT_GROUP = "5m", "fast", "subject"


def register(subparsers) -> None:
    p = subparsers.add_parser("train", help="train teacher policies (InterMimic imitation-as-retargeting)",
                              description=__doc__)
    p.add_argument("stage", nargs="?", default="teacher", choices=["teacher", "student"],
                   help="teacher (default) or student (distillation from teachers)")
    p.add_argument("--embodiment", default="g1_inspire",
                   help="robot: a name under configs/embodiments/ or a YAML path (robot-hoi model show lists it)")
    p.add_argument("--data", nargs="*", default=None,
                   help="clip files or folders (.pt InterMimic format, .npz native); default: the embedded clip. "
                        "Put the stage (student) before --data, or end the list with --")
    add_clip_options(p)
    p.add_argument("--group", default=None, choices=["subject", "object", "clip"],
                   help="one teacher per group (default: the recipe's, else per subject, as InterMimic)")
    p.add_argument("--budget", default=None,
                   help="training length, split evenly over the groups: wall time in s, m (minutes), h, d (90s, "
                        "10m, 2h), samples in k, M (millions), G (200k, 5M) or iterations (300it); combine with "
                        "commas (2h,50M: whichever comes first). Lower-case m is minutes, capital M is millions. "
                        f"A recipe's budget, else {DEFAULT_BUDGET} (default: {DEFAULT_BUDGET})")
    p.add_argument("--recipe", default=None, metavar="NAME",
                   help=f"a run as a file: a configs/recipes/ name ({', '.join(recipe_names())}) or YAML path "
                        "(robot_hoi/rl/recipe.py); flags and --set given here override it; the run folder records it "
                        f"as {RECORD_FILE}")
    seeds = p.add_mutually_exclusive_group()
    seeds.add_argument("--seed", type=int, default=None,
                       help="the training seed (the training config's seed, as --set seed=N); default: the config's")
    seeds.add_argument("--seeds", type=int, nargs="+", default=None, metavar="N",
                       help="train the same run once per seed, one after another, into OUT/seed_<n>/ (each a run "
                            "folder of its own, --resume continues each); the budget is each seed's")
    p.add_argument("--out", default=None, help="run folder (default: ./runs/<date>-<embodiment> in the current "
                                               "directory)")
    p.add_argument("--preset", default=None, choices=sorted(PRESETS),
                   help="PPO settings: paper = InterMimic Table C (tuned for 8192 GPU envs), fast = CPU-sized "
                        f"(default: the recipe's, else {DEFAULT_PRESET})")
    p.add_argument("--config", default=None, help="a training YAML instead of the preset")
    p.add_argument("--task-config", default=str(TASK_CONFIG), help="environment YAML")
    p.add_argument("--rewards", default=None, metavar="SET",
                   help=f"reward formulation: a configs/tasks/rewards/ name ({', '.join(reward_set_names())}) "
                        "or YAML path; default: the recipe's, else the task config's")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   help="override, e.g. --set env.num_envs=128 --set retarget.solver=qp --set ppo.actor_lr=1e-4 "
                        "(repeatable; env.KEY and retarget.KEY: the task config, configs/tasks/interaction.yaml)")
    p.add_argument("--resume", action="store_true", help="continue each group from its latest checkpoint")
    p.add_argument("--skip-gate", action="store_true", default=None,
                   help="train on references that fail the physics gate (robot-hoi retarget: the reference replayed "
                        "with the pelvis held loses the object or a held contact); default: the recipe's, else "
                        "refuse them")
    p.add_argument("--init", default=None, metavar="CHECKPOINT",
                   help="start each teacher from this policy's weights and normalisers (a base policy or another "
                        "clip's teacher; same observation layout), with fresh optimiser and counters; ignored where "
                        "a group resumes. Default: the shipped base policy policies/base_<embodiment>.pt when there "
                        "is one; 'none' trains from scratch")
    p.add_argument("--backend", default=None, choices=["auto", "cpu", "warp"],
                   help="physics: cpu (mujoco.rollout), warp (MuJoCo Warp; a GPU, or warp's CPU device) or auto "
                        "(warp when a CUDA device is present); default: the task config's (auto) for teachers, "
                        "cpu for the student")
    p.add_argument("--device", default="auto",
                   help="policy/PPO device: cpu, cuda[:N] or auto (where the physics runs; cuda under a Ray GPU)")
    p.add_argument("--nproc", type=int, default=None,
                   help="student: data-parallel processes (default: the CUDA devices with --device cuda when more "
                        "than one, else 1)")
    p.add_argument("--torch-threads", type=int, default=1,
                   help="torch CPU threads (default 1: the physics pool owns the cores; small-batch ops lose "
                        "more to thread hand-offs than they gain)")
    p.add_argument("--eval-episodes", type=int, default=4,
                   help="episodes per clip for each teacher's eval.json after training (default 4)")
    c = p.add_argument_group("distributed teachers (robot_hoi/rl/cluster.py)")
    c.add_argument("--cluster", default="none", choices=["none", "ray"],
                   help="none: teachers one after another here; ray: one Ray task per teacher group")
    c.add_argument("--address", default=None,
                   help="Ray cluster address (e.g. auto, 10.0.0.5:6379, ray://head:10001); default: a local instance")
    c.add_argument("--cpus-per-teacher", type=float, default=1.0, help="Ray CPUs per teacher task (default 1)")
    c.add_argument("--gpus-per-teacher", type=float, default=None,
                   help="Ray GPUs per teacher task (default: 1 if the cluster has GPUs, else 0)")
    c.add_argument("--max-retries", type=int, default=3,
                   help="re-runs of a failed or pre-empted teacher; each resumes from its last checkpoint")
    c.add_argument("--storage", default="auto", choices=["auto", "shared", "local"],
                   help="auto: detect whether workers see the run folder; shared: they must; local: workers "
                        "train in their temp folder and send the results back")
    p.add_argument("--teachers", nargs="+", default=None, metavar="RUN_DIR",
                   help="student: the teacher run folder(s) (the --out of `robot-hoi train`); several folders, "
                        "or clips of several objects, give a student of many skills")
    p.add_argument("--option", dest="options", action="append", default=[],
                   help="student: a configs/train/student_options preset, e.g. complexmimic, skillmimic_v2 (repeatable)")
    p.set_defaults(func=run)


def _stage_from_data(args: argparse.Namespace) -> None:
    """`train --data X student`: --data takes any number of values, so argparse files the stage under it."""
    from robot_hoi.errors import UserError

    stages = [d for d in args.data or [] if d in ("teacher", "student") and not Path(d).exists()]
    if not stages:
        return
    if len(stages) > 1 or args.stage != "teacher":
        raise UserError(f"give the stage once, got {', '.join([args.stage, *stages])}")
    args.stage = stages[0]
    args.data = [d for d in args.data if d != stages[0]] or None


def run(args: argparse.Namespace) -> int:
    from robot_hoi.errors import UserError

    _stage_from_data(args)
    if args.stage == "student" and (args.recipe or args.seeds or args.seed is not None):
        raise UserError("--recipe, --seed and --seeds train teachers; the student's settings are --option and --set")
    if args.seeds:
        return _train_seeds(args)
    if args.seed is not None:
        if any(o.partition("=")[0].strip() == "seed" for o in args.overrides):
            raise UserError("--seed and --set seed= both set the seed: give one")
        args.overrides = [f"seed={args.seed}", *args.overrides]
    if args.backend is not None:
        args.overrides = [*args.overrides, f"env.backend={args.backend}"]
    recipe = _apply_recipe_flags(args)
    if args.stage == "student":
        if args.cluster != "none":
            raise UserError("--cluster trains teachers; the student trains here (drop --cluster)")
        import torch

        from robot_hoi.student.launch import run as train_student

        if args.device == "auto":
            args.device = "cuda" if torch.cuda.is_available() else "cpu"

        return train_student(args)
    import json
    import uuid

    import torch

    from deploy.atomic import atomic_write_text
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.rl import recipe as recipes
    from robot_hoi.rl.budget import parse_budget
    from robot_hoi.rl.config import load_train_config
    from robot_hoi.rl.teacher_job import PREEMPT_HOOK_ENV, TeacherJob, format_line, print_summary
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, apply_reward_set, split_overrides
    from robot_hoi.utils.config import apply_overrides, load_yaml_dataclass

    if args.eval_episodes < 1:
        raise UserError(f"--eval-episodes must be at least 1, got {args.eval_episodes}")
    torch.set_num_threads(max(args.torch_threads, 1))
    env_overrides, train_overrides = split_overrides(args.overrides)
    embodiment = load_embodiment(args.embodiment)
    env_cfg = load_yaml_dataclass(InteractionEnvCfg, args.task_config)
    if args.rewards:
        apply_reward_set(env_cfg, args.rewards)
    if recipe is not None:
        env_cfg = recipe.apply("retarget", recipe.apply("env", env_cfg))
    env_cfg = apply_overrides(env_cfg, env_overrides, "--set")
    env_cfg.embodiment = embodiment.name
    train_cfg = load_train_config(args.config or PRESETS[args.preset])
    if recipe is not None:
        train_cfg = recipe.apply("train", train_cfg)
    train_cfg = apply_overrides(train_cfg, train_overrides, "--set")
    budget = parse_budget(args.budget)

    init = base_policy_init(args.init, embodiment.name)
    sources = factory.expand_sources(args.data)
    options = clip_options(args)
    clips = [factory.load_source(s, options) for s in sources]
    for clip in clips:
        if clip.object is not None:
            print(f"{clip.name}: object {clip.object_name} from {clip.object.origin}")
    groups = factory.group_sources(sources, clips, args.group)
    out = Path(args.out) if args.out else _default_out(embodiment.name)
    if not args.skip_gate:
        _physics_gate(clips, groups, out, env_cfg, embodiment)
    print(f"training {len(groups)} teacher(s) on {len(clips)} clip(s) -> {out}")
    flags = {key: getattr(args, key) for key in recipes.FLAGS}
    recipes.write_record(out, recipes.resolved(recipe, flags, args.overrides), recipe)
    per_group = _split_budget(budget, len(groups))
    token = uuid.uuid4().hex
    jobs = [TeacherJob(group=name, sources=[sources[i] for i in members], run_dir=str(out / name),
                       embodiment=embodiment.name, env_cfg=env_cfg, train_cfg=train_cfg, budget=per_group,
                       run_token=token, device=args.device, torch_threads=max(args.torch_threads, 1),
                       resume=args.resume, init=init, init_is_default=args.init is None, eval_episodes=args.eval_episodes,
                       preempt_marker_dir=os.environ.get(PREEMPT_HOOK_ENV) or None, clip_options=options)
            for name, members in groups.items()]
    group_clips = [[clips[i] for i in members] for members in groups.values()]
    if args.cluster == "ray":
        from robot_hoi.rl.cluster import RayOptions, run_teachers

        options = RayOptions(address=args.address, cpus_per_teacher=args.cpus_per_teacher,
                             gpus_per_teacher=args.gpus_per_teacher, max_retries=args.max_retries,
                             storage=args.storage)
        summaries, failures = run_teachers(jobs, group_clips, options, resume=args.resume)
    else:
        from robot_hoi.rl.teacher_job import train_teacher_group

        summaries, failures = {}, {}
        for k, (job, job_clips) in enumerate(zip(jobs, group_clips, strict=True), start=1):
            summaries[job.group] = train_teacher_group(job, job_clips)
            print(f"[{k}/{len(jobs)}] {format_line(summaries[job.group])}")
    report = {"cluster": args.cluster, "budget_per_teacher": per_group.describe(), "teachers": summaries,
              "failures": failures}
    atomic_write_text(out / SUMMARY_FILE, json.dumps(report, indent=2) + "\n")
    print_summary(summaries, failures, title=f"robot-hoi train: {out}")
    if failures:
        print(f"{len(failures)} of {len(jobs)} teacher(s) failed: {', '.join(failures)}")
        return 1
    print(f"done: {out}")
    return 0


def _apply_recipe_flags(args: argparse.Namespace):
    """Load --recipe (None without one) and fill the flags not given on the command line from it, then from
    their defaults."""
    from robot_hoi.rl.recipe import load_recipe

    recipe = load_recipe(args.recipe) if args.recipe else None
    settings = recipe.settings if recipe is not None else {}
    defaults = {"budget": DEFAULT_BUDGET, "preset": DEFAULT_PRESET, "group": DEFAULT_GROUP, "skip_gate": False}
    for key in FLAGS:
        if getattr(args, key) is None:
            setattr(args, key, settings.get(key, defaults.get(key)))
    return recipe


def _train_seeds(args: argparse.Namespace) -> int:
    """`--seeds`: the same run once per seed, one after another, into OUT/seed_<n>/."""
    import copy
    from collections import Counter

    from robot_hoi.errors import UserError

    repeated = sorted(s for s, n in Counter(args.seeds).items() if n > 1)
    if repeated:
        raise UserError(f"--seeds: seed {', '.join(map(str, repeated))} given more than once")
    if any(o.partition("=")[0].strip() == "seed" for o in args.overrides):
        raise UserError("--seeds sets each run's seed: drop --set seed=")
    if args.out:
        out = Path(args.out)
    else:
        from robot_hoi.embodiment import load_embodiment

        out = _default_out(load_embodiment(args.embodiment).name)
    codes = {}
    for k, seed in enumerate(args.seeds, start=1):
        one = copy.copy(args)
        one.seeds, one.seed, one.out = None, seed, str(out / f"seed_{seed}")
        one.overrides = list(args.overrides)
        print(f"=== seed {seed} ({k} of {len(args.seeds)}) -> {one.out}")
        codes[seed] = run(one)
    for seed, code in codes.items():
        print(f"seed {seed}: {out / f'seed_{seed}'}{'' if code == 0 else f' (failed, exit {code})'}")
    return max(codes.values())


def _default_out(embodiment: str) -> Path:
    import time

    return Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{embodiment}"


def _physics_gate(clips: list, groups: dict[str, list[int]], out: Path, env_cfg, embodiment) -> None:
    """Refuse references that fail the physics gate (robot_hoi.tasks.interaction.feasibility), each retargeted
    into its teacher's reference cache."""
    from robot_hoi.errors import UserError
    from robot_hoi.tasks.interaction.feasibility import format_verdict, gate_failures

    folder = {i: out / name / "references" for name, members in groups.items() for i in members}
    failed = gate_failures(clips, env_cfg, embodiment, [folder[i] for i in range(len(clips))])
    if failed:
        reasons = "; ".join(f"{name}: {format_verdict(gate)}" for name, gate in failed)
        raise UserError(f"physics gate: {reasons}. The reference loses the object with the pelvis held and no "
                        "residual; --skip-gate trains anyway")


def _split_budget(budget, parts: int):
    """Each group gets an equal share of the wall time / samples / iterations."""
    from dataclasses import replace

    share = {k: (None if v is None else type(v)(max(v / parts, 1))) for k, v in
             (("wall_seconds", budget.wall_seconds), ("samples", budget.samples), ("iterations", budget.iterations))}
    return replace(budget, **share)


def base_policy_init(init: str | None, embodiment: str) -> str | None:
    """The checkpoint teachers start from: `--init` as given ('none': from scratch), else the shipped base policy
    of the embodiment when the repository has one."""
    from robot_hoi.errors import UserError
    from robot_hoi.paths import POLICIES_DIR

    if init is not None:
        if init.lower() == "none":
            return None
        if not Path(init).is_file():
            raise UserError(f"{init}: no such checkpoint to start the teachers from (--init)")
        return init
    shipped = POLICIES_DIR / f"base_{embodiment}.pt"
    if shipped.is_file():
        print(f"teachers start from the shipped base policy {shipped} (--init none trains from scratch)")
        return str(shipped)
    return None

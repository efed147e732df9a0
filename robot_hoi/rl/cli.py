"""`robot-hoi train`: InterMimic teachers (one per group) on the embodiment, from clips or the embedded default."""

from __future__ import annotations

import argparse
from pathlib import Path

from robot_hoi.paths import CONFIGS_DIR, REPO_ROOT

TASK_CONFIG = CONFIGS_DIR / "tasks" / "interaction.yaml"
PRESETS = {"paper": CONFIGS_DIR / "train" / "ppo.yaml", "fast": CONFIGS_DIR / "train" / "ppo_fast.yaml"}


def register(subparsers) -> None:
    p = subparsers.add_parser("train", help="train teacher policies (InterMimic imitation-as-retargeting)",
                              description=__doc__)
    p.add_argument("stage", nargs="?", default="teacher", choices=["teacher", "student"],
                   help="teacher (default) or student (distillation from teachers)")
    p.add_argument("--embodiment", default="g1_inspire")
    p.add_argument("--data", nargs="*", default=None,
                   help="clip files or folders (.pt InterMimic format, .npz native); default: the embedded clip")
    p.add_argument("--group", default="subject", choices=["subject", "object", "clip"],
                   help="one teacher per group (default: per subject, as InterMimic)")
    p.add_argument("--budget", default="5m", help="wall time (90s, 10m, 2h) or samples (200k, 5M); split evenly "
                                                  "over the groups")
    p.add_argument("--out", default=None, help="run folder (default runs/<date>-<embodiment>)")
    p.add_argument("--preset", default="fast", choices=sorted(PRESETS),
                   help="PPO settings: paper = InterMimic Table C (tuned for 8192 GPU envs), fast = CPU-sized")
    p.add_argument("--config", default=None, help="a training YAML instead of the preset")
    p.add_argument("--task-config", default=str(TASK_CONFIG), help="environment YAML")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   help="override, e.g. --set env.num_envs=128 --set ppo.actor_lr=1e-4 (repeatable)")
    p.add_argument("--resume", action="store_true", help="continue each group from its latest checkpoint")
    p.add_argument("--device", default="cpu")
    p.add_argument("--torch-threads", type=int, default=1,
                   help="torch CPU threads (default 1: the physics pool owns the cores; small-batch ops lose "
                        "more to thread hand-offs than they gain)")
    p.add_argument("--teachers", default=None, help="student: the teacher run folder (the --out of `robot-hoi train`)")
    p.add_argument("--option", dest="options", action="append", default=[],
                   help="student: a configs/train/student_options preset, e.g. complexmimic, skillmimic_v2 (repeatable)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.stage == "student":
        from robot_hoi.student.pipeline import run as train_student

        return train_student(args)
    import time

    import torch

    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.rl.budget import parse_budget
    from robot_hoi.rl.config import load_train_config
    from robot_hoi.rl.runner import OnPolicyRunner
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.utils.config import load_yaml_dataclass

    torch.set_num_threads(max(args.torch_threads, 1))
    env_overrides = [o[len("env."):] for o in args.overrides if o.startswith("env.")]
    train_overrides = [o for o in args.overrides if not o.startswith("env.")]
    embodiment = load_embodiment(args.embodiment)
    env_cfg = load_yaml_dataclass(InteractionEnvCfg, args.task_config, env_overrides)
    env_cfg.embodiment = embodiment.name
    train_cfg = load_train_config(args.config or PRESETS[args.preset], train_overrides)
    budget = parse_budget(args.budget)

    sources = factory.expand_sources(args.data)
    clips = [factory.load_source(s) for s in sources]
    groups = factory.group_sources(sources, clips, args.group)
    out = Path(args.out) if args.out else REPO_ROOT / "runs" / f"{time.strftime('%Y%m%d-%H%M%S')}-{embodiment.name}"
    print(f"training {len(groups)} teacher(s) on {len(clips)} clip(s) -> {out}")
    per_group = _split_budget(budget, len(groups))
    summary = {}
    for name, members in groups.items():
        run_dir = out / name
        run_dir.mkdir(parents=True, exist_ok=True)
        group_clips = [clips[i] for i in members]
        group_sources = [sources[i] for i in members]
        factory.write_task(run_dir, group_sources, env_cfg, embodiment.name, name)
        torch.manual_seed(train_cfg.seed)
        env = factory.make_env(group_clips, env_cfg, embodiment, cache=run_dir / "references")
        runner = OnPolicyRunner(env, train_cfg, run_dir, device=args.device)
        if args.resume:
            latest = _latest_checkpoint(run_dir)
            if latest is not None:
                runner.resume(latest)
                print(f"[{name}] resumed from {latest}")
        print(f"[{name}] {len(group_clips)} clip(s): {', '.join(c.name for c in group_clips)}; "
              f"obs {env.obs_dims}, {env.num_envs} envs")
        summary[name] = runner.learn(per_group)
        runner.close()
    for name, stats in summary.items():
        shown = {k: round(v, 3) for k, v in stats.items() if isinstance(v, float)}
        print(f"[{name}] {shown}")
    print(f"done: {out}")
    return 0


def _split_budget(budget, parts: int):
    """Each group gets an equal share of the wall time / samples / iterations."""
    from dataclasses import replace

    share = {k: (None if v is None else type(v)(max(v / parts, 1))) for k, v in
             (("wall_seconds", budget.wall_seconds), ("samples", budget.samples), ("iterations", budget.iterations))}
    return replace(budget, **share)


def _latest_checkpoint(run_dir: Path) -> Path | None:
    final = run_dir / "model_final.pt"
    if final.exists():
        return final
    found = sorted(run_dir.glob("model_*.pt"), key=lambda p: int(p.stem.split("_")[-1]) if
                   p.stem.split("_")[-1].isdigit() else -1)
    return found[-1] if found else None

"""`robot-hoi eval`: InterMimic's metrics for a teacher checkpoint (or an untrained baseline), per clip.

Every episode starts from the default stand at the clip's start (with the 15-frame approach warmup), actions are
the policy mean, and an episode ends at the clip's end or at an (interaction) early termination. Metrics:
success rate, duration (s) until termination, E_h (cm, mean mapped-link position error excluding the hands) and
E_o (cm, mean object surface-point error), both averaged over the imitated duration.
"""

from __future__ import annotations

import argparse
import json

from robot_hoi.data.cli_options import add_clip_options, clip_options
from robot_hoi.paths import TASK_CONFIG


def register(subparsers) -> None:
    p = subparsers.add_parser("eval", help="evaluate a checkpoint: success, duration, E_h, E_o per clip",
                              description=__doc__)
    p.add_argument("checkpoint", help="a model_*.pt from `robot-hoi train` or `robot-hoi train student`, a run or "
                                      "group folder (its latest checkpoint), or `untrained` for a baseline")
    p.add_argument("--data", nargs="*", default=None, help="clips (default: the ones the checkpoint trained on)")
    add_clip_options(p)
    p.add_argument("--embodiment", default="g1_inspire",
                   help="robot: a name under configs/embodiments/ or a YAML path")
    p.add_argument("--episodes", type=int, default=8, help="episodes per clip (run in parallel)")
    p.add_argument("--preset", default="fast", choices=["fast", "paper"], help="network for `untrained`")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="environment override on top of the checkpoint's task config, e.g. --set "
                        "env.self_collision=true (repeatable; the evaluation protocol's own settings still apply)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.rl.checkpoint import load_policy
    from robot_hoi.rl.cli import PRESETS
    from robot_hoi.rl.config import load_train_config
    from robot_hoi.rl.models import ActorCritic
    from robot_hoi.sim.device import resolve_env_cfg
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.utils.config import load_dataclass, load_yaml_dataclass

    if args.checkpoint == "untrained":
        env_cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)
        sources = factory.expand_sources(args.data)
        options = clip_options(args)
        model = ckpt = None
    else:
        from robot_hoi.rl.checkpoint import resolve_checkpoint

        ckpt = resolve_checkpoint(args.checkpoint)
        from robot_hoi.student.checkpoint import is_student_checkpoint

        if is_student_checkpoint(ckpt):
            from robot_hoi.student.eval_checkpoint import run_student_eval

            return run_student_eval(args, ckpt)
        model, _, _ = load_policy(ckpt)
        task = factory.read_task(ckpt) if args.data is None else None
        env_cfg = load_dataclass(InteractionEnvCfg, task["env"], f"{ckpt} task") if task else \
            load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)
        sources = task["sources"] if task else factory.expand_sources(args.data)
        options = clip_options(args, task.get("clip_options") if task else None)
    embodiment = load_embodiment(args.embodiment)
    evaluation_settings(env_cfg, args.episodes, args.seed)
    env_cfg = apply_env_overrides(env_cfg, args.overrides)  # after: `--set` may evaluate under other settings
    env_cfg = resolve_env_cfg(env_cfg)  # once: every clip's env on the same device, the model moved there

    results = {}
    for source in sources:
        clip = factory.load_source(source, options)
        cache = ckpt.parent / "references" if ckpt is not None and (ckpt.parent / "references").is_dir() else None
        env = factory.make_env([clip], env_cfg, embodiment, cache=cache)
        if model is None:
            torch.manual_seed(args.seed)
            train_cfg = load_train_config(PRESETS[args.preset])
            model = ActorCritic(env.obs_dims["policy"], env.obs_dims["critic"], env.num_actions, train_cfg.model)
            model.eval()
        results[clip.name] = evaluate(env, model.to(env.device))
    summary = summarise(results)
    if args.json:
        print(json.dumps({"checkpoint": str(ckpt or args.checkpoint), "clips": results, "mean": summary}, indent=2))
    else:
        _print_table(str(ckpt or args.checkpoint), results, summary)
    return 0


def apply_env_overrides(env_cfg, overrides: list[str]):
    """`--set` values for the environment: "env.key=value" or "key=value" (InteractionEnvCfg keys)."""
    from robot_hoi.utils.config import apply_overrides

    items = [o[len("env."):] if o.startswith("env.") else o for o in overrides]
    return apply_overrides(env_cfg, items, "--set") if items else env_cfg


def evaluation_settings(env_cfg, episodes: int, seed: int) -> None:
    """Turn a training env config into the evaluation one (in place): `episodes` stand starts, no noise, no PSI,
    no assist wrenches, no domain randomisation (the clip's own object)."""
    from robot_hoi.tasks.interaction.env_cfg import RandomizationCfg

    env_cfg.num_envs = episodes
    env_cfg.seed = seed
    env_cfg.init.stand_start_probability = 1.0
    env_cfg.init.spawn_noise_xy = 0.0
    env_cfg.psi.enabled = False
    env_cfg.assist.enabled = False  # a training curriculum: never in evaluation
    env_cfg.randomization = RandomizationCfg()


def evaluate(env, model, stochastic: bool = False) -> dict[str, float]:
    """Run each env until its first episode ends; average InterMimic's metrics over those episodes.

    Actions are the policy mean, or samples of the policy's Gaussian with `stochastic` (seed torch first). The
    model runs where its parameters are, the env where its physics is: observations and actions cross over."""
    import torch

    from robot_hoi.sim.device import module_device

    policy_device = module_device(model, env.device)
    obs = env.reset()
    finished: dict[str, list[torch.Tensor]] = {}
    counted = torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)
    returns = torch.zeros(env.num_envs, device=env.device)
    with torch.no_grad():
        for _ in range(env.max_episode_length + env.cfg.warmup_frames + 2):
            policy_obs = obs["policy"].to(policy_device)
            actions = model.act(policy_obs) if stochastic else model.act_inference(policy_obs)
            obs, reward, terminated, truncated, extras = env.step(actions.to(env.device))
            returns += torch.where(counted, 0.0, reward)
            done = terminated | truncated
            new = done & ~counted
            if new.any():
                keep = new[done]  # rows of extras["episode"] that belong to first episodes
                for key, value in extras["episode"].items():
                    finished.setdefault(key, []).append(value[keep])
                counted |= new
            if counted.all():
                break
    stats = {k: torch.cat(v) for k, v in finished.items()}
    return {
        "episodes": int(counted.sum()),
        "success_rate": stats["success"].mean().item(),
        # success that also tracked the object and body (env_cfg success_max_*): a policy that reaches the clip's
        # end without doing the interaction has success but not this
        "interaction_success_rate": stats["interaction_success"].mean().item(),
        "duration_s": stats["duration_s"].mean().item(),
        "E_h_cm": stats["E_h_cm"].mean().item(),
        "E_o_cm": stats["E_o_cm"].mean().item(),
        "E_o_max_cm": stats["E_o_max_cm"].mean().item(),
        "return": returns[counted].mean().item(),
        # share of the episodes each termination ended (several can fire on one step; none: the clip's end)
        "ended_by": {k.split("/", 1)[1]: v.mean().item() for k, v in stats.items() if k.startswith("ended_by/")},
        "clip_duration_s": env.total_frames / env.references[0].fps,
        # how executable the reference is (robot_hoi.retarget.feasibility), when the env knows
        "reference_feasibility": (getattr(env, "reference_feasibility", None) or [None])[0],
    }


SUMMARY_METRICS = ("success_rate", "interaction_success_rate", "duration_s", "E_h_cm", "E_o_cm", "E_o_max_cm", "return")


def summarise(results: dict[str, dict[str, float]]) -> dict[str, float]:
    """Mean over clips of each per-clip metric (teachers and students alike)."""
    return {k: sum(r[k] for r in results.values()) / max(len(results), 1) for k in SUMMARY_METRICS}


def _print_table(name: str, results, summary) -> None:
    from rich.table import Table

    from robot_hoi.utils.console import table_console

    table = Table()
    for col in ("clip", "episodes", "success", "interaction", "duration (s)", "E_h (cm)", "E_o (cm)", "E_o max"):
        table.add_column(col, justify="right" if col != "clip" else "left")
    for clip, r in results.items():
        table.add_row(clip, str(r["episodes"]), f"{r['success_rate']:.2f}", f"{r['interaction_success_rate']:.2f}",
                      f"{r['duration_s']:.2f} / {r['clip_duration_s']:.2f}", f"{r['E_h_cm']:.1f}",
                      f"{r['E_o_cm']:.1f}", f"{r['E_o_max_cm']:.1f}")
    table.add_row("mean", "", f"{summary['success_rate']:.2f}", f"{summary['interaction_success_rate']:.2f}",
                  f"{summary['duration_s']:.2f}", f"{summary['E_h_cm']:.1f}", f"{summary['E_o_cm']:.1f}",
                  f"{summary['E_o_max_cm']:.1f}")
    console = table_console()
    # the heading on its own line: a table title wraps at the table's width, splitting long checkpoint paths
    console.print(f"robot-hoi eval: {name}", markup=False, highlight=False)
    console.print(table)
    for clip, r in results.items():
        ended = ", ".join(f"{k} {v:.2f}" for k, v in sorted(r["ended_by"].items(), key=lambda kv: -kv[1]) if v > 0)
        print(f"{clip}: episodes ended by {ended or 'the clip end (no termination)'}")

"""One teacher group from start to finish: train into its folder, resume after a pre-emption, evaluate.

`train_teacher_group(job)` is the single code path of `robot-hoi train`: the sequential loop calls it in-process
and `--cluster ray` calls it inside one Ray task per group (robot_hoi/rl/cluster.py).

Group folder (beside the runner's checkpoints and logs):
  task.json        clips and environment config (robot_hoi.tasks.interaction.factory.write_task)
  job_state.json   the run token of the `robot-hoi train` invocation that owns the folder and the counters it
                   started from. A retry of the same invocation (same token: a Ray task re-run after a crash or
                   pre-emption) resumes from the latest checkpoint and trains only the budget left; a new
                   invocation starts afresh, or with `--resume` continues with a fresh budget.
  eval.json        InterMimic's metrics of the final policy (robot_hoi.rl.evaluation.evaluate), per clip and mean;
                   under "best", the same for model_best.pt (the in-training evaluation's pick, runner.eval_interval).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import torch
from rich import box
from rich.table import Table

from deploy.atomic import atomic_write_text
from robot_hoi.embodiment import load_embodiment
from robot_hoi.rl.budget import Budget
from robot_hoi.rl.checkpoint import BEST_CHECKPOINT, latest_checkpoint, load_model_state, read_checkpoint
from robot_hoi.rl.eval_curve import EVAL_CURVE_FILE
from robot_hoi.rl.evaluation import (
    DEFAULT_PROTOCOL,
    VALIDATION_SEED,
    evaluate,
    load_protocol,
    protocol_env_cfg,
    selection_env_cfg,
    summarise,
    validation_label,
)
from robot_hoi.rl.runner import OnPolicyRunner
from robot_hoi.sim.device import check_gpu_memory, policy_device, resolve_env_cfg
from robot_hoi.tasks.interaction import factory
from robot_hoi.utils.console import table_console

JOB_STATE_FILE = "job_state.json"
EVAL_FILE = "eval.json"
SCALARS_FILE = "scalars.jsonl"
# Test-only hook: a folder; the first periodic checkpoint of each group then kills the process once (as a
# pre-empted node would), leaving <folder>/<group>.preempted so that the retry trains on. A file <folder>/lose_disk
# makes the dying process delete its group folder first (the node and its disk are gone: the retry runs elsewhere).
PREEMPT_HOOK_ENV = "ROBOT_HOI_TEST_PREEMPT_AFTER_CHECKPOINT"
PREEMPT_EXIT_CODE = 75


@dataclass
class TeacherJob:
    """Everything a worker needs to train one group (picklable; paths are strings as seen by the worker)."""

    group: str
    sources: list[str]  # clip sources recorded in task.json (factory.expand_sources)
    run_dir: str  # the group folder
    embodiment: str
    env_cfg: Any  # InteractionEnvCfg
    train_cfg: Any  # TrainConfig
    budget: Budget
    run_token: str  # one per `robot-hoi train` invocation
    device: str = "cpu"
    torch_threads: int = 1
    resume: bool = False  # --resume: continue from the latest checkpoint even if another invocation wrote it
    init: str | None = None  # --init: weights and normalisers to start from (not when resuming)
    init_is_default: bool = False  # init is the shipped base policy, not asked for: from scratch where it does not fit
    eval_episodes: int = 4  # episodes per clip for eval.json
    eval_seed: int = 0
    preempt_marker_dir: str | None = None  # PREEMPT_HOOK_ENV, read by the driver
    clip_options: dict = field(default_factory=dict)  # load_clip keywords (--objects, --repair), into task.json

    def at(self, run_dir: str | Path) -> TeacherJob:
        """The same job writing into another folder (a worker's local staging folder)."""
        return replace(self, run_dir=str(run_dir))


def read_job_state(run_dir: Path) -> dict | None:
    path = Path(run_dir) / JOB_STATE_FILE
    try:
        state = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None  # absent, or written by something else: treated as a new invocation
    return state if isinstance(state, dict) and "run_token" in state else None


def remaining_budget(budget: Budget, state: dict, iteration: int, samples: int, time_s: float) -> Budget | None:
    """What is left of this invocation's budget after the counters moved from `state`'s start; None: spent."""
    left = {
        "wall_seconds": None if budget.wall_seconds is None else
        budget.wall_seconds - (time_s - state["start_time_s"]),
        "samples": None if budget.samples is None else budget.samples - (samples - state["start_samples"]),
        "iterations": None if budget.iterations is None else
        budget.iterations - (iteration - state["start_iteration"]),
    }
    if any(v is not None and v <= 0 for v in left.values()):
        return None
    return Budget(**left)


def train_teacher_group(job: TeacherJob, clips: list | None = None, log=print,
                        on_checkpoint: Callable[[Path], None] | None = None) -> dict[str, Any]:
    """Train (or finish training) one group in job.run_dir, evaluate it, write eval.json; return a summary.

    `clips` are the loaded clips of job.sources (loaded here when None; a Ray task receives them from the
    driver, so clip files need not exist on the worker). `on_checkpoint(path)` runs after each periodic
    checkpoint (a Ray worker without shared storage mirrors the folder to the driver there)."""
    started = time.monotonic()
    torch.set_num_threads(max(job.torch_threads, 1))
    run_dir = Path(job.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    if clips is None:
        clips = [factory.load_source(s, job.clip_options) for s in job.sources]
    embodiment = load_embodiment(job.embodiment)
    factory.write_task(run_dir, job.sources, job.env_cfg, embodiment.name, job.group, job.clip_options)

    state = read_job_state(run_dir)
    same_invocation = state is not None and state["run_token"] == job.run_token
    latest = latest_checkpoint(run_dir)
    resume_from = latest if latest is not None and (job.resume or same_invocation) else None
    if latest is not None and resume_from is None:
        log(f"[{job.group}] starting afresh in a folder with checkpoints of an earlier run (--resume continues "
            f"from {latest.name})")
    if resume_from is not None:
        # Rows logged after that checkpoint are re-trained now; drop them so the log has each iteration once.
        resumed_iteration = int(read_checkpoint(resume_from)["iteration"])
        for log_file in (SCALARS_FILE, EVAL_CURVE_FILE):
            _trim_log(run_dir / log_file, resumed_iteration)

    torch.manual_seed(job.train_cfg.seed)
    # The physics device, chosen once in this process (a Ray worker: its own GPU); training and evaluation envs
    # are built from this resolved config (task.json keeps the requested one, re-resolved where it is read).
    env_cfg = resolve_env_cfg(job.env_cfg)
    check_gpu_memory(env_cfg)
    env = factory.make_env(clips, env_cfg, embodiment, cache=run_dir / "references")
    runner = OnPolicyRunner(env, job.train_cfg, run_dir, device=policy_device(job.device, env.device))
    runner.on_checkpoint = on_checkpoint
    if job.train_cfg.runner.eval_interval:
        # model selection: the randomized protocol on validation seeds, disjoint from `robot-hoi eval`'s, so the
        # score eval reports is not the one model_best.pt was picked on; envs built once and re-seeded: every
        # checkpoint meets the same starts
        validation_seed = VALIDATION_SEED + job.eval_seed
        validation = evaluation_envs(clips, selection_env_cfg(env_cfg, job.train_cfg.runner.eval_episodes,
                                                              validation_seed), embodiment, run_dir / "references")
        runner.evaluator = lambda model: {**summarise(evaluate_envs(validation, model, validation_seed)),
                                          **validation_label(env_cfg)}
        runner.on_evaluation = lambda row: log(
            f"[{job.group}] eval at it {row['step']} ({row['train_time_s'] / 60:.1f} min): success "
            f"{row['success_rate']:.2f}, duration {row['duration_s']:.2f} s, E_h {row['E_h_cm']:.1f} cm, E_o "
            f"{row['E_o_cm']:.1f} cm{' (best so far: model_best.pt)' if row['best'] else ''}")
    resumed_from = None
    if resume_from is not None:
        runner.resume(resume_from)
        resumed_from = runner.iteration
        log(f"[{job.group}] resumed from {resume_from.name} (iteration {runner.iteration})")
    elif job.init:
        reason = runner.initialise_from(job.init, required=not job.init_is_default)
        if reason is None:
            log(f"[{job.group}] initialised from {job.init}")
        else:
            log(f"[{job.group}] training from scratch: the shipped base policy {job.init} does not fit this run "
                f"({reason})")
    if not same_invocation:
        state = {"run_token": job.run_token, "start_iteration": runner.iteration,
                 "start_samples": runner.total_samples, "start_time_s": runner.total_time_s}
        atomic_write_text(run_dir / JOB_STATE_FILE, json.dumps(state, indent=2) + "\n")
    if job.preempt_marker_dir:
        _arm_preemption(runner, Path(job.preempt_marker_dir) / f"{job.group}.preempted")

    budget = remaining_budget(job.budget, state, runner.iteration, runner.total_samples, runner.total_time_s)
    log(f"[{job.group}] {len(clips)} clip(s): {', '.join(c.name for c in clips)}; obs {env.obs_dims}, "
        f"{env.num_envs} envs; budget {'spent' if budget is None else budget.describe()}")
    if budget is not None:
        stats = runner.learn(budget)
    else:
        stats = {"iterations": 0.0, "samples": 0.0, "wall_s": 0.0, "mean_return": float("nan")}
    runner.close()
    checkpoint = run_dir / f"model_{runner.iteration}.pt"  # learn() always ends with this one
    checkpoint = checkpoint if checkpoint.exists() else latest_checkpoint(run_dir)

    # robot-hoi eval's default protocol and seeds, in envs of the training env's (resolved) config
    eval_cfg = protocol_env_cfg(env_cfg, load_protocol(DEFAULT_PROTOCOL)[1], job.eval_episodes, job.eval_seed)
    envs = evaluation_envs(clips, eval_cfg, embodiment, run_dir / "references")
    evaluation = _evaluation_record(evaluate_envs(envs, runner.model.eval(), job.eval_seed), job)
    evaluation.update(group=job.group, checkpoint=checkpoint.name if checkpoint else None,
                      iteration=runner.iteration)
    best = run_dir / BEST_CHECKPOINT
    if best.exists():  # the policy the run stands for (checkpoint.policy_checkpoint), by the same protocol
        best_data = read_checkpoint(best)
        load_model_state(runner.model, best_data["model"], best)
        evaluation["best"] = _evaluation_record(evaluate_envs(envs, runner.model.eval(), job.eval_seed), job)
        evaluation["best"].update(checkpoint=best.name, iteration=int(best_data["iteration"]),
                                  selected_by=best_data.get("eval"))
    atomic_write_text(run_dir / EVAL_FILE, json.dumps(evaluation, indent=2) + "\n")
    return {
        "group": job.group,
        "iteration": runner.iteration,
        "iterations": int(stats["iterations"]),
        "samples": int(stats["samples"]),
        "train_s": float(stats["wall_s"]),
        "wall_s": time.monotonic() - started,
        "mean_return": _finite_or_none(stats["mean_return"]),  # none before any episode ended in this call
        "resumed_from": resumed_from,
        "checkpoint": evaluation["checkpoint"],
        "eval": evaluation["mean"],
        "best": {"iteration": evaluation["best"]["iteration"], **evaluation["best"]["mean"]} if "best" in evaluation
        else None,
        "host": socket.gethostname(),
        "run_dir": str(run_dir),
    }


def evaluation_envs(clips: list, eval_cfg, embodiment, cache: Path) -> dict[str, Any]:
    """One env per clip from an evaluation config (protocol_env_cfg or selection_env_cfg of the training env's
    resolved config: where the model is)."""
    return {clip.name: factory.make_env([clip], eval_cfg, embodiment, cache=cache) for clip in clips}


def evaluate_envs(envs: dict[str, Any], model, seed: int) -> dict[str, dict]:
    """evaluation.evaluate on each env, its generator re-seeded first: reused envs give every policy the same
    starts."""
    results = {}
    for name, env in envs.items():
        env.generator.manual_seed(seed)
        results[name] = evaluate(env, model)
    return results


def _evaluation_record(results: dict[str, dict], job: TeacherJob) -> dict[str, Any]:
    return {"protocol": DEFAULT_PROTOCOL, "episodes_per_clip": job.eval_episodes, "seed": job.eval_seed,
            "clips": results,
            "mean": summarise(results)}


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _trim_log(path: Path, last_step: int) -> None:
    """Drop the rows of a per-iteration JSONL log (scalars, eval curve) after `last_step`."""
    if not path.exists():
        return
    lines = path.read_text().splitlines(keepends=True)
    kept = [line for line in lines if _step(line) <= last_step]
    if len(kept) != len(lines):
        atomic_write_text(path, "".join(kept))


def _step(line: str) -> float:
    try:
        return float(json.loads(line)["step"])
    except (ValueError, KeyError, TypeError):
        return float("inf")  # a torn last line from a killed process goes too


def _arm_preemption(runner, marker: Path) -> None:
    """Test hook: after the first periodic checkpoint, die once like a pre-empted node (no clean-up)."""
    if marker.exists():
        return
    save = runner._save_periodic

    def save_then_die() -> None:
        save()
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(f"pre-empted after iteration {runner.iteration}\n")
        if (marker.parent / "lose_disk").exists():
            shutil.rmtree(runner.log_dir, ignore_errors=True)
        os._exit(PREEMPT_EXIT_CODE)

    runner._save_periodic = save_then_die


def format_line(summary: dict[str, Any]) -> str:
    """One progress line per finished teacher."""
    ev = summary["eval"]
    resumed = "" if summary["resumed_from"] is None else f" (resumed at {summary['resumed_from']})"
    return (f"{summary['group']}: it {summary['iteration']}{resumed}, return {_number(summary['mean_return'])}, "
            f"success {ev['success_rate']:.2f} (interaction {ev.get('interaction_success_rate', float('nan')):.2f}), "
            f"E_h {ev['E_h_cm']:.1f} cm, E_o {ev['E_o_cm']:.1f} cm, "
            f"{summary['wall_s']:.0f} s on {summary['host']}{_best_text(summary.get('best'))}")


def _best_text(best: dict | None) -> str:
    if best is None:
        return ""
    return (f"; model_best.pt (it {best['iteration']}): success {best['success_rate']:.2f}, "
            f"{best['duration_s']:.2f} s tracked")


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"


def print_summary(summaries: dict[str, dict], failures: dict[str, str], title: str) -> None:
    """The final table: one row per teacher (failed ones with their error)."""
    table = Table(title=title, box=box.SIMPLE_HEAD, pad_edge=False, show_edge=False, collapse_padding=True)
    for col in ("teacher", "it", "return", "success", "dur s", "E_h cm", "E_o cm", "wall s"):  # host: in the lines
        table.add_column(col, justify="left" if col == "teacher" else "right",
                         no_wrap=col == "teacher", min_width=len(col))
    for name, s in summaries.items():
        ev = s["eval"]
        table.add_row(name, str(s["iteration"]), _number(s["mean_return"]), f"{ev['success_rate']:.2f}",
                      f"{ev['duration_s']:.2f}", f"{ev['E_h_cm']:.1f}", f"{ev['E_o_cm']:.1f}", f"{s['wall_s']:.0f}")
    for name in failures:
        table.add_row(name, "-", "failed", *[""] * 5)
    console = table_console()
    console.print(table)
    for name, error in failures.items():
        console.print(f"{name}: {error}", markup=False, highlight=False)

"""teacher_job: one group trained in-process (the sequential path), retried with the same run token (what a Ray
re-run does) and continued by a new invocation with --resume; budgets left after a partial run."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
import torch

from robot_hoi.rl.budget import Budget
from robot_hoi.rl.config import FAST_PPO_CONFIG, load_train_config
from robot_hoi.rl.teacher_job import (
    EVAL_FILE,
    JOB_STATE_FILE,
    SCALARS_FILE,
    TeacherJob,
    remaining_budget,
    train_teacher_group,
)
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg


def test_remaining_budget_subtracts_what_this_invocation_already_did():
    state = {"start_iteration": 10, "start_samples": 1000, "start_time_s": 5.0}
    left = remaining_budget(Budget(wall_seconds=60, samples=5000, iterations=8), state, 13, 1600, 25.0)
    assert left == Budget(wall_seconds=40.0, samples=4400, iterations=5)
    assert remaining_budget(Budget(iterations=3), state, 13, 1600, 25.0) is None
    assert remaining_budget(Budget(samples=600, iterations=100), state, 11, 1600, 25.0) is None


@pytest.fixture
def job(tmp_path):
    torch.set_num_threads(1)
    env_cfg = InteractionEnvCfg(num_envs=4, nthread=1)
    train_cfg = load_train_config(FAST_PPO_CONFIG, ["runner.progress=false", "runner.tensorboard=false",
                                                    "runner.save_interval=1"])
    return TeacherJob(group="push", sources=["embedded:push"], run_dir=str(tmp_path / "push"),
                      embodiment="g1_inspire", env_cfg=env_cfg, train_cfg=train_cfg, budget=Budget(iterations=2),
                      run_token="first", eval_episodes=2)


def _steps(folder) -> list[int]:
    return [json.loads(line)["step"] for line in (folder / SCALARS_FILE).read_text().splitlines()]


@pytest.mark.slow
def test_retry_resumes_with_what_is_left_and_resume_continues(job, tmp_path):
    folder = tmp_path / "push"
    first = train_teacher_group(job, log=lambda _: None)
    assert first["iteration"] == 2 and first["resumed_from"] is None and first["checkpoint"] == "model_2.pt"
    assert json.loads((folder / JOB_STATE_FILE).read_text())["run_token"] == "first"
    evaluation = json.loads((folder / EVAL_FILE).read_text())
    assert evaluation["iteration"] == 2 and evaluation["clips"]["synth_push_seed0"]["episodes"] == 2

    # the same invocation again (a Ray re-run after the task already finished its budget): no new iterations,
    # and a log row written after the checkpoint by the killed attempt is dropped
    with (folder / SCALARS_FILE).open("a") as f:
        f.write(json.dumps({"step": 3, "Loss/value": 1.0}) + "\n" + '{"step": 4, "Loss/va')
    retry = train_teacher_group(job, log=lambda _: None)
    assert retry["resumed_from"] == 2 and retry["iterations"] == 0 and retry["iteration"] == 2
    assert _steps(folder) == [1, 2]

    # a new invocation with --resume continues with a fresh budget
    again = train_teacher_group(replace(job, run_token="second", resume=True), log=lambda _: None)
    assert again["resumed_from"] == 2 and again["iteration"] == 4 and _steps(folder) == [1, 2, 3, 4]
    assert json.loads((folder / EVAL_FILE).read_text())["checkpoint"] == "model_4.pt"


@pytest.mark.slow
def test_init_starts_a_new_run_from_another_runs_policy(job, tmp_path):
    from robot_hoi.rl.checkpoint import read_checkpoint

    base = train_teacher_group(job, log=lambda _: None)
    base_ckpt = tmp_path / "push" / base["checkpoint"]
    logs = []
    clip = replace(job, run_dir=str(tmp_path / "clip"), run_token="clip", budget=Budget(iterations=1),
                   train_cfg=replace(job.train_cfg, seed=job.train_cfg.seed + 7), init=str(base_ckpt))
    started = train_teacher_group(clip, log=logs.append)
    assert started["iteration"] == 1 and any("initialised from" in line for line in logs)  # counters start afresh
    ours, theirs = read_checkpoint(tmp_path / "clip" / "model_1.pt"), read_checkpoint(base_ckpt)
    # one PPO iteration moved the weights a little from the base policy's, not from a fresh initialisation
    name = next(k for k in theirs["model"] if k.startswith("actor") and k.endswith("weight"))
    drift = (ours["model"][name] - theirs["model"][name]).abs().mean()
    assert drift < 0.1 * theirs["model"][name].abs().mean()


def test_a_shipped_base_that_does_not_fit_trains_from_scratch_but_an_asked_for_one_is_an_error(job, tmp_path):
    from robot_hoi.errors import UserError

    base = train_teacher_group(job, log=lambda _: None)
    base_ckpt = str(tmp_path / "push" / base["checkpoint"])
    smaller = replace(job.train_cfg, model=replace(job.train_cfg.model, actor_hidden_dims=[32]))
    clip = replace(job, run_dir=str(tmp_path / "clip"), run_token="clip", budget=Budget(iterations=1),
                   train_cfg=smaller, init=base_ckpt, init_is_default=True)
    logs = []
    assert train_teacher_group(clip, log=logs.append)["iteration"] == 1
    assert any("training from scratch" in line and "actor." in line for line in logs)
    asked = replace(clip, run_dir=str(tmp_path / "asked"), run_token="asked", init_is_default=False)
    with pytest.raises(UserError, match="network differs"):
        train_teacher_group(asked, log=lambda _: None)


def test_teachers_start_from_the_shipped_base_policy_unless_told(tmp_path, monkeypatch):
    from robot_hoi import paths
    from robot_hoi.commands.train import base_policy_init
    from robot_hoi.errors import UserError

    monkeypatch.setattr(paths, "POLICIES_DIR", tmp_path)
    assert base_policy_init(None, "g1_inspire") is None  # nothing shipped: from scratch
    (tmp_path / "base_g1_inspire.pt").write_bytes(b"weights")
    assert base_policy_init(None, "g1_inspire") == str(tmp_path / "base_g1_inspire.pt")
    assert base_policy_init("none", "g1_inspire") is None
    with pytest.raises(UserError, match="no such checkpoint"):
        base_policy_init(str(tmp_path / "missing.pt"), "g1_inspire")


def test_in_training_evaluation_writes_a_curve_and_the_run_stands_for_its_best(job, tmp_path):
    from robot_hoi.rl.checkpoint import read_checkpoint, resolve_checkpoint
    from robot_hoi.rl.eval_curve import EVAL_CURVE_FILE, find_curves, summarize

    logs = []
    job = replace(job, train_cfg=replace(job.train_cfg, runner=replace(job.train_cfg.runner, eval_interval=1,
                                                                       eval_episodes=2)))
    train_teacher_group(job, log=logs.append)
    folder = tmp_path / "push"
    rows = [json.loads(line) for line in (folder / EVAL_CURVE_FILE).read_text().splitlines()]
    assert [r["step"] for r in rows] == [1, 2] and rows[0]["best"]
    assert all(r["duration_s"] > 0.0 and r["E_h_cm"] > 0.0 for r in rows)  # episodes of the real env were run
    assert sum("eval at it" in line for line in logs) == 2
    best_row = [r for r in rows if r["best"]][-1]
    assert read_checkpoint(folder / "model_best.pt")["iteration"] == best_row["step"]
    assert resolve_checkpoint(folder) == folder / "model_best.pt"
    (curve,) = find_curves([str(tmp_path)])  # what `robot-hoi curve` reads: the same rows, the same best
    assert curve.rows == rows and summarize(curve.rows)["best"]["step"] == best_row["step"]
    evaluation = json.loads((folder / EVAL_FILE).read_text())
    assert evaluation["best"]["iteration"] == best_row["step"] and evaluation["best"]["checkpoint"] == "model_best.pt"
    assert evaluation["best"]["clips"]["synth_push_seed0"]["episodes"] == 2

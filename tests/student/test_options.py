"""Every option as a config switch (--option / --set) and a tiny run of each option through the CLI."""

import json

import pytest
import torch

from robot_hoi.cli import main
from robot_hoi.errors import UserError
from robot_hoi.rl.checkpoint import latest_checkpoint
from robot_hoi.student.config import (
    STUDENT_CONFIG,
    STUDENT_FAST_CONFIG,
    load_student_config,
    option_overrides,
)

from .conftest import student_args


def test_option_presets_set_what_they_say():
    cfg, env = load_student_config(STUDENT_FAST_CONFIG, ["complexmimic"])
    assert cfg.complexmimic.enabled and (cfg.distill.loss, cfg.distill.weights, cfg.distill.beta) == ("kl", "fixed", 0)
    assert env == ["num_envs=64", "psi.enabled=false"]  # the fast preset's env count, then the option's
    assert load_student_config(STUDENT_CONFIG)[1] == []  # the paper preset keeps the teachers' env count
    assert load_student_config(STUDENT_FAST_CONFIG, overrides=["env.num_envs=8"])[1] == ["num_envs=64", "num_envs=8"]
    with pytest.raises(UserError, match="num_envs must be positive"):
        load_student_config(STUDENT_FAST_CONFIG, overrides=["num_envs=0"])
    cfg, _ = load_student_config(STUDENT_FAST_CONFIG, ["skillmimic_v2"])
    assert cfg.skillmimic.enabled and cfg.skillmimic.history and cfg.skillmimic.max_masked == 10
    cfg, _ = load_student_config(STUDENT_FAST_CONFIG, ["skillmimic_deployable"])
    assert cfg.skillmimic.enabled and not cfg.skillmimic.history
    cfg, _ = load_student_config(STUDENT_FAST_CONFIG, ["ppo_only"])
    assert (cfg.distill.weights, cfg.distill.lambda_ppo, cfg.distill.lambda_kd, cfg.distill.beta) == ("fixed", 1, 0, 0)
    assert load_student_config(STUDENT_CONFIG)[0].distill.weights == "schedule"  # the paper preset: DAgger -> PPO
    cfg, _ = load_student_config(STUDENT_CONFIG, ["dagger_only"])
    assert (cfg.distill.weights, cfg.distill.lambda_ppo, cfg.distill.lambda_kd) == ("fixed", 0.0, 1.0)
    cfg, _ = load_student_config(STUDENT_FAST_CONFIG, ["no_reference_distillation"],
                                 ["distill.reference=teacher"])  # --set wins over an option
    assert cfg.distill.reference == "teacher"
    assert option_overrides("no_reference_distillation") == ['distill.reference="mocap"']
    with pytest.raises(UserError, match="known: "):
        option_overrides("nope")


@pytest.mark.slow
def test_complexmimic_run(teacher_run, tmp_path, capsys):
    out = tmp_path / "cm"
    assert main(student_args(teacher_run, out, "--option", "complexmimic", "--set", "complexmimic.update_every=1",
                             budget="4it")) == 0
    printed = capsys.readouterr().out
    assert "fine-tuning the imitation expert" in printed and "fine-tuning the interaction expert" in printed
    routing = json.loads((out / "routing.json").read_text())
    info = routing["synth_lift_place_seed0"]
    assert info["group"] == ("imitation" if info["imitation_success"] >= 0.5 else "interaction")
    for kind, groups in (("imitation", ["policy"]), ("interaction", ["policy", "height_map"])):
        ckpt = next((out / "experts" / "synthetic-tall_box" / kind).glob("model_*.pt"))
        data = torch.load(ckpt, weights_only=True)
        assert data["obs_layout"]["actor_groups"] == groups
        task = json.loads((ckpt.parent / "task.json").read_text())
        assert task["env"]["terminations"]["max_mean_link_error"] == (0.25 if kind == "imitation" else 0.5)
    task = json.loads((out / "student" / "task.json").read_text())
    assert task["env"]["terminations"]["max_mean_link_error"] == 0.5 and not task["env"]["psi"]["enabled"]
    assert task["clip_teacher"] == [info["expert"]]
    rows = [json.loads(line) for line in (out / "student" / "scalars.jsonl").read_text().splitlines()]
    assert "Distill/kl" in rows[-1] and any("Sampling/max_probability" in r for r in rows)
    # the height map is the interaction expert's: the student reads the deployable observation and exports
    export_and_check(latest_checkpoint(out / "student"), tmp_path / "cm.onnx", capsys)


@pytest.mark.slow
def test_skillmimic_run_and_export_refusal(teacher_run, tmp_path, capsys):
    out = tmp_path / "sm"
    assert main(student_args(teacher_run, out, "--option", "skillmimic_v2", "--set",
                             "skillmimic.history_pretrain_steps=100")) == 0
    assert "history encoder pre-trained" in capsys.readouterr().out
    assert (out / "history_encoder.pt").is_file()
    ckpt = out / "student" / "model_2.pt"
    data = torch.load(ckpt, weights_only=True)
    assert data["obs_layout"]["actor_groups"] == ["student", "history"]
    assert "start_sampler" in data["sampler_state"] and "ats" in data["sampler_state"]
    rows = [json.loads(line) for line in (out / "student" / "scalars.jsonl").read_text().splitlines()]
    assert "Sampling/masked_frames_mean" in rows[-1]
    assert main(["export", "onnx", str(ckpt), "-o", str(tmp_path / "x.onnx")]) == 2
    err = capsys.readouterr().err
    assert "no history observation" in err and "skillmimic_deployable" in err and not (tmp_path / "x.onnx").exists()
    # it evaluates with its frozen history encoder rebuilt from the run folder
    assert main(["eval", str(ckpt), "--episodes", "1", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["kind"] == "student" and report["clips"]["synth_lift_place_seed0"]["ours"]["episodes"] == 1


def test_ablation_run_without_reference_distillation(teacher_run, tmp_path, capsys):
    out = tmp_path / "ppo"
    assert main(student_args(teacher_run, out, "--option", "no_reference_distillation", "--option", "ppo_only",
                             "--set", "eval_episodes=0")) == 0
    task = json.loads((out / "student" / "task.json").read_text())
    assert task["references"] == [None] and not (out / "references").exists()
    rows = [json.loads(line) for line in (out / "student" / "scalars.jsonl").read_text().splitlines()]
    assert [r["Distill/w_distill"] for r in rows] == [0.0, 0.0] and rows[0]["Distill/student_fraction"] == 1.0
    export_and_check(out / "student" / "model_2.pt", tmp_path / "ppo.onnx", capsys)
    assert "198 frames" in capsys.readouterr().out  # the sidecar is the whole MoCap retarget (lift_place)


def export_and_check(ckpt, onnx_file, capsys):
    assert main(["export", "onnx", str(ckpt), "-o", str(onnx_file), "--recorded", "32"]) == 0
    assert main(["export", "check", str(onnx_file), "--embodiment", "g1_inspire"]) == 0
    printed = capsys.readouterr().out
    assert "policy_kind student" in printed and "matches embodiment g1_inspire" in printed
    print(printed)  # for the caller


def test_deployable_skillmimic_student_exports(teacher_run, tmp_path, capsys):
    out = tmp_path / "smd"
    assert main(student_args(teacher_run, out, "--option", "skillmimic_deployable", "--option", "dagger_only",
                             "--set", "skillmimic.neighbourhood_probability=1.0", "--set", "eval_episodes=0")) == 0
    rows = [json.loads(line) for line in (out / "student" / "scalars.jsonl").read_text().splitlines()]
    assert [r["Distill/w_ppo"] for r in rows] == [0.0, 0.0] and [r["Distill/w_distill"] for r in rows] == [1.0, 1.0]
    assert all("Sampling/masked_frames_mean" in r for r in rows) and not (out / "history_encoder.pt").exists()
    export_and_check(out / "student" / "model_2.pt", tmp_path / "smd.onnx", capsys)


def test_students_train_with_the_runtime_target_rate_limit():
    """A student's env limits how fast PD targets move exactly as the robot runtime does (a student trained
    without it fell in sim2sim's turns, where the runtime cut its target steps); a limit the config sets stays."""
    from deploy.safety import SafetyConfig
    from robot_hoi.student.task import student_env_cfg
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg

    teacher = InteractionEnvCfg()
    assert teacher.command_rate_limit is None
    assert student_env_cfg(teacher).command_rate_limit == SafetyConfig().max_target_rate == 10.0
    teacher.command_rate_limit = 6.0
    assert student_env_cfg(teacher).command_rate_limit == 6.0

"""End to end through the CLI: a tiny teacher on the embedded clip -> a distilled student -> ONNX -> contract
check -> deploy dry run. Small networks and few envs keep it well under 90 s on two busy cores."""

import json

import numpy as np
import pytest

from deploy.contract import PolicyContract
from deploy.motion import load_motion
from robot_hoi.cli import main
from robot_hoi.student.checkpoint import load_student

from .conftest import student_args


@pytest.mark.slow
def test_distil_export_check_and_dry_run(teacher_run, tmp_path, capsys):
    out = tmp_path / "student"
    assert main(student_args(teacher_run, out)) == 0
    printed = capsys.readouterr().out
    assert "[reference] synth_lift_place_seed0" in printed and "student (MoCap)" in printed
    ckpt = out / "student" / "model_2.pt"
    model, cfg, data = load_student(ckpt)
    assert cfg.runner.actor_obs_groups == ["student"] and model.layout.keyframes == (1, 2, 4, 16)
    task = json.loads((out / "student" / "task.json").read_text())
    assert task["references"] == ["../references/synth_lift_place_seed0.npz"]
    assert (out / "references" / "synth_lift_place_seed0.npz").is_file()
    report = json.loads((out / "student" / "eval.json").read_text())
    assert set(report) == {"teacher synthetic-tall_box (MoCap)", "student (its reference)", "student (MoCap)"}

    # resume continues the run and reuses the distilled reference
    assert main([*student_args(teacher_run, out), "--resume", "--set", "eval_episodes=0"]) == 0
    assert "reusing" in capsys.readouterr().out
    assert load_student(out / "student" / "model_4.pt")[2]["iteration"] == 4

    onnx_file = tmp_path / "student.onnx"
    assert main(["export", "onnx", str(ckpt), "-o", str(onnx_file), "--recorded", "64"]) == 0
    printed = capsys.readouterr().out
    assert "ORT vs torch max |diff|" in printed and (tmp_path / "student.motion.npz").is_file()
    assert main(["export", "check", str(onnx_file), "--embodiment", "g1_inspire"]) == 0
    assert "policy_kind student" in capsys.readouterr().out
    # a zero action targets the reference joints: they must be reachable, or deploy clamps every tick
    contract = PolicyContract.from_onnx(onnx_file)
    motion = load_motion(tmp_path / "student.motion.npz")
    targets = np.stack([contract.action_to_target(np.zeros(contract.num_actions), q) for q in motion.joint_pos])
    assert np.all((targets >= contract.joint_lower) & (targets <= contract.joint_upper))

    log_dir = tmp_path / "deploy"
    assert main(["deploy", "--dry-run", "--policy", str(onnx_file), "--duration", "5", "--auto-start",
                 "--hand-bus", "can", "--log-dir", str(log_dir)]) == 0
    summary = json.loads((log_dir / "summary.json").read_text())
    assert summary["phase_time_s"].get("POLICY", 0.0) > 0.0


@pytest.mark.slow
def test_an_object_free_student_exports_a_policy_that_needs_no_tracker(teacher_run, tmp_path, capsys):
    """--option object_free: the actor reads proprioception and the reference only (the critic keeps the object);
    its export says tracker [] and the dry run opens none."""
    out = tmp_path / "student"
    assert main(student_args(teacher_run, out, "--option", "object_free", "--set", "eval_episodes=0")) == 0
    model, cfg, data = load_student(out / "student" / "model_2.pt")
    names = [t["name"] for t in data["student"]["obs_spec"]]
    assert "object_pos" not in names and "ref_link_pos" not in names and "ref_root_local" in names
    assert data["dims"]["critic_obs"] > data["dims"]["actor_obs"]  # the critic still sees the object (privileged)
    onnx_file = tmp_path / "free.onnx"
    assert main(["export", "onnx", str(out / "student" / "model_2.pt"), "-o", str(onnx_file)]) == 0
    contract = PolicyContract.from_onnx(onnx_file)
    assert contract.tracked_poses == () and not contract.needs_tracker
    import onnx

    metadata = {p.key: p.value for p in onnx.load(str(onnx_file)).metadata_props}
    assert json.loads(metadata["tracker"]) == []
    log_dir = tmp_path / "deploy"
    assert main(["deploy", "--dry-run", "--policy", str(onnx_file), "--duration", "4", "--auto-start",
                 "--log-dir", str(log_dir)]) == 0
    summary = json.loads((log_dir / "summary.json").read_text())
    assert summary["setup"]["tracker"] == "none (the policy reads no tracked pose)"
    assert summary["phase_time_s"].get("POLICY", 0.0) > 0.0


@pytest.mark.slow
def test_stable_student_selects_on_validation_and_records_why(teacher_run, tmp_path, capsys):
    """--option stable: validation on the randomized protocol keeps model_best.pt (the weight average), and
    selection.json holds the choice, its validation row and its neighbours'."""
    out = tmp_path / "student"
    assert main(student_args(teacher_run, out, "--option", "stable", "--set", "runner.eval_interval=2",
                             "--set", "runner.eval_episodes=2", "--set", "eval_episodes=0", budget="6it")) == 0
    assert "[student] validation at it 2" in capsys.readouterr().out
    folder = out / "student"
    selection = json.loads((folder / "selection.json").read_text())
    curve = [json.loads(line) for line in (folder / "eval_curve.jsonl").read_text().splitlines()]
    assert [row["step"] for row in curve] == [2, 4, 6] and selection["evaluations"] == 3
    assert selection["checkpoint"] == "model_best.pt" and selection["iteration"] in (2, 4, 6)
    assert selection["validation"] == {"protocol": "randomized", "seed": 100_001, "episodes_per_clip": 2,
                                       "every_iterations": 2,
                                       "randomization": "none (the protocol's starts only)"}
    assert selection["weights"].startswith("exponential moving average, decay 0.98")
    assert selection["actor_lr"] == {"half_life_iterations": 100, "floor": 0.1}
    assert 1 <= len(selection["neighbours"]) <= 2 and 0.0 <= selection["neighbour_success_spread"] <= 1.0
    best = load_student(folder / "model_best.pt")[2]
    assert best["iteration"] == selection["iteration"] and "ema_model" in best


def test_student_cli_errors_are_one_line(tmp_path, capsys):
    assert main(["train", "student", "--budget", "1it"]) == 2
    assert "--teachers" in capsys.readouterr().err
    assert main(["train", "student", "--teachers", str(tmp_path), "--budget", "1it"]) == 2
    assert "no teacher groups" in capsys.readouterr().err
    assert main(["train", "student", "--teachers", str(tmp_path), "--option", "nope"]) == 2
    assert "known: " in capsys.readouterr().err


def test_two_teachers_one_student(tmp_path, capsys):
    from .conftest import QUIET

    teachers = tmp_path / "teachers"
    assert main(["train", "--data", "embedded:lift_carry", "embedded:lift_place", "--group", "clip", "--budget", "2it",
                 "--skip-gate", "--out", str(teachers), *QUIET, "--set", "model.actor_hidden_dims=[32]",
                 "--set", "model.critic_hidden_dims=[32]"]) == 0
    groups = sorted(p.name for p in teachers.iterdir() if p.is_dir())
    assert len(groups) == 2
    out = tmp_path / "student"
    assert main(student_args(teachers, out, "--set", "eval_episodes=0", "--set", "distill.reference=mocap")) == 0
    task = json.loads((out / "student" / "task.json").read_text())
    assert len(task["sources"]) == 2 and sorted(task["clip_teacher"]) == groups
    capsys.readouterr()

    # teachers trained with other observation settings cannot share one student env
    import shutil

    mixed = tmp_path / "mixed"
    shutil.copytree(teachers, mixed)
    task_file = mixed / groups[1] / "task.json"
    changed = json.loads(task_file.read_text())
    changed["env"]["keyframes"] = [1, 8]
    task_file.write_text(json.dumps(changed))
    assert main(student_args(mixed, tmp_path / "refused")) == 2
    assert "different task settings (keyframes)" in capsys.readouterr().err


@pytest.mark.slow
def test_a_student_of_two_objects_exports_one_sidecar_per_skill(teacher_run, tmp_path, capsys):
    """Teachers of the tall box (lift_place) and of the 5 kg box (a walk past it): one student, one env per object;
    its export lists both clips as skills with their sidecars; a dry run picks a skill by name and sim2sim's
    default targets are every skill on its own object."""
    from sim2sim.targets import policy_targets

    from .conftest import QUIET
    walk = tmp_path / "walk_teacher"
    assert main(["train", "--data", "embedded:walk:0", "--budget", "2it", "--out", str(walk), *QUIET,
                 "--set", "model.actor_hidden_dims=[32]", "--set", "model.critic_hidden_dims=[32]"]) == 0
    out = tmp_path / "student"
    assert main(student_args([teacher_run, walk], out, "--set", "eval_episodes=0")) == 0
    printed = capsys.readouterr().out
    assert "2 objects, one env each: tall_box (1 clip(s), 2 envs), box (1 clip(s), 2 envs)" in printed
    task = json.loads((out / "student" / "task.json").read_text())
    assert task["sources"] == ["embedded:lift_place", "embedded:walk:0"]

    onnx_file = tmp_path / "multi.onnx"
    assert main(["export", "onnx", str(out / "student" / "model_2.pt"), "-o", str(onnx_file),
                 "--clip", "synth_walk_seed0"]) == 0
    contract = PolicyContract.from_onnx(onnx_file)
    assert list(contract.skills) == ["synth_walk_seed0", "synth_lift_place_seed0"]
    assert contract.reference.file == "multi.motion.npz"  # the default skill's
    lift_path, lift_info = contract.skill_reference("synth_lift_place_seed0")
    assert lift_path.name == "multi.synth_lift_place_seed0.motion.npz"
    lift = load_motion(lift_path, expected_sha256=lift_info.sha256)
    assert not np.allclose(lift.object_pos[0], load_motion(tmp_path / "multi.motion.npz").object_pos[0])

    log_dir = tmp_path / "deploy"
    assert main(["deploy", "--dry-run", "--policy", str(onnx_file), "--skill", "synth_lift_place_seed0",
                 "--duration", "4", "--auto-start", "--log-dir", str(log_dir)]) == 0
    assert json.loads((log_dir / "summary.json").read_text())["phase_time_s"].get("POLICY", 0.0) > 0.0
    assert main(["deploy", "--dry-run", "--policy", str(onnx_file), "--skill", "squat", "--duration", "4",
                 "--auto-start"]) != 0
    assert "no skill 'squat'" in capsys.readouterr().err

    targets = policy_targets(contract, None, "g1_inspire", True)
    assert [(t.name, t.object_name) for t in targets] == [("synth_walk_seed0", "box"),
                                                          ("synth_lift_place_seed0", "tall_box")]
    one = policy_targets(contract, str(lift_path), "g1_inspire", True)
    assert [(t.name, t.object_name) for t in one] == [("synth_lift_place_seed0", "tall_box")]

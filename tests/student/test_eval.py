"""`robot-hoi eval` on a student checkpoint: the teachers' metrics, against the MoCap retarget and the distilled
reference, equal to what the training run's own evaluation measured with the same protocol."""

import json

import pytest

from robot_hoi.cli import main

from .conftest import student_args

CLIP = "synth_lift_place_seed0"


@pytest.fixture(scope="module")
def student_run(teacher_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("student_eval")
    assert main(student_args(teacher_run, out, "--set", "eval_episodes=2", budget="1it")) == 0
    return out


def eval_json(capsys, *args) -> dict:
    capsys.readouterr()
    assert main(["eval", *map(str, args), "--episodes", "2", "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_student_eval_matches_the_runs_own_evaluation(student_run, capsys):
    # the run's own evaluation starts from the one deterministic stand: so does `--protocol stand`
    report = eval_json(capsys, student_run / "student" / "model_1.pt", "--protocol", "stand")
    assert report["kind"] == "student"
    assert set(report["clips"]) == {CLIP} and set(report["distilled"]["clips"]) == {CLIP}
    trained = json.loads((student_run / "student" / "eval.json").read_text())
    for ours, theirs in ((report["clips"][CLIP], trained["student (MoCap)"][CLIP]),
                         (report["distilled"]["clips"][CLIP], trained["student (its reference)"][CLIP])):
        assert ours["ours"]["episodes"] == 2
        assert ours["ours"]["success"]["rate"] == pytest.approx(theirs["success_rate"])
        for key in ("duration_s", "E_h_cm", "E_o_cm"):
            assert ours["ours"][key]["mean"] == pytest.approx(theirs[key], rel=1e-5, abs=1e-6), key
    # the distilled reference is the teacher's shorter rollout, not the clip
    assert report["distilled"]["clips"][CLIP]["clip_duration_s"] < report["clips"][CLIP]["clip_duration_s"]
    assert report["overall"]["ours"]["E_h_cm"]["mean"] == pytest.approx(report["clips"][CLIP]["ours"]["E_h_cm"]["mean"])


@pytest.mark.slow
def test_student_eval_on_given_clips_and_as_a_table(student_run, capsys):
    ckpt = student_run / "student" / "model_1.pt"
    report = eval_json(capsys, ckpt, "--data", "embedded:lift_place")
    assert set(report["clips"]) == {CLIP} and "distilled" not in report
    assert report["clips"] == eval_json(capsys, ckpt)["clips"]  # the same clip, the same MoCap retarget
    assert main(["eval", str(ckpt), "--episodes", "1"]) == 0
    printed = capsys.readouterr().out
    assert "robot-hoi eval (its distilled reference)" in printed and "E_h cm" in printed
    assert "protocol randomized: 1 episodes per clip, seed 0" in printed


def test_student_eval_errors_are_one_line(student_run, tmp_path, capsys):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(student_run, copy)
    shutil.rmtree(copy / "references")
    assert main(["eval", str(copy / "student" / "model_1.pt")]) == 2
    assert "distilled reference is missing" in capsys.readouterr().err

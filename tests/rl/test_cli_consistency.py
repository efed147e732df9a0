"""Commands as a new user meets them: defaults that do not surprise, messages that name what exists."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from robot_hoi.cli import build_parser, main
from robot_hoi.commands.train import _stage_from_data
from robot_hoi.rl.checkpoint import resolve_checkpoint


def _help(*command: str) -> str:
    parser = build_parser()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            sub = action.choices[command[0]]
            for name in command[1:]:
                sub = next(a for a in sub._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
            return sub.format_help()
    raise AssertionError(command)


def test_help_lists_units_and_defaults():
    train = " ".join(_help("train").split())
    assert "m (minutes)" in train and "M (millions)" in train and "(default: 5m)" in train
    assert "robot: a name under configs/embodiments/" in train and "(default: g1_inspire)" in train
    sim2sim = " ".join(_help("sim2sim").split())
    assert "(default: 0.8)" in sim2sim and "E_h (cm" in sim2sim
    assert "(default: 1000)" in " ".join(_help("export", "onnx").split())


def test_stage_after_data_is_the_stage(tmp_path, monkeypatch):
    args = argparse.Namespace(data=["clip.pt", "student"], stage="teacher")
    _stage_from_data(args)
    assert args.stage == "student" and args.data == ["clip.pt"]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "student").mkdir()  # a folder really named student stays a clip folder
    args = argparse.Namespace(data=["student"], stage="teacher")
    _stage_from_data(args)
    assert args.stage == "teacher" and args.data == ["student"]


def test_run_folders_resolve_to_their_latest_checkpoint(tmp_path):
    group = tmp_path / "run" / "sub1-box"
    group.mkdir(parents=True)
    for it in (5, 50, 10):
        (group / f"model_{it}.pt").write_bytes(b"")
    assert resolve_checkpoint(tmp_path / "run") == group / "model_50.pt"
    assert resolve_checkpoint(group) == group / "model_50.pt"
    (tmp_path / "run" / "sub2-box").mkdir()
    (tmp_path / "run" / "sub2-box" / "model_1.pt").write_bytes(b"")
    with pytest.raises(Exception, match="several groups"):
        resolve_checkpoint(tmp_path / "run")


def test_a_folder_with_a_best_checkpoint_resolves_to_it_but_resumes_from_the_latest(tmp_path):
    from robot_hoi.rl.checkpoint import latest_checkpoint, policy_checkpoint

    for it in (25, 50):
        (tmp_path / f"model_{it}.pt").write_bytes(b"")
    (tmp_path / "model_best.pt").write_bytes(b"")
    assert resolve_checkpoint(tmp_path) == tmp_path / "model_best.pt"
    assert policy_checkpoint(tmp_path) == tmp_path / "model_best.pt"
    assert latest_checkpoint(tmp_path) == tmp_path / "model_50.pt"


def test_export_without_a_checkpoint_does_not_pick_one(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "runs" / "r" / "g").mkdir(parents=True)
    (tmp_path / "runs" / "r" / "g" / "model_3.pt").write_bytes(b"")
    assert main(["export", "onnx"]) == 2
    err = capsys.readouterr().err
    assert "name the checkpoint" in err and "runs/r/g/model_3.pt" in err


def test_inspect_shows_no_agreement_when_nothing_was_inferred(lift_clip_no_contacts):
    from robot_hoi.data.summary import clip_summary, format_summary

    report = clip_summary(lift_clip_no_contacts)
    assert report["contact"]["agreement"] is None
    assert "no contact inferred, nothing to compare" in format_summary(report)


@pytest.fixture
def lift_clip_no_contacts():
    from robot_hoi.data.synth import default_clip

    clip = default_clip("lift_carry")
    clip.inferred_contact = np.zeros_like(clip.inferred_contact)
    return clip


@pytest.mark.slow
def test_train_eval_export_check_as_a_user(tmp_path, monkeypatch, capsys):
    """train writes under ./runs of the current directory; eval takes the run folder; a teacher's export check
    says it cannot be deployed."""
    monkeypatch.chdir(tmp_path)
    assert main(["train", "--budget", "1it", "--eval-episodes", "1", "--set", "env.num_envs=4",
                 "--set", "ppo.horizon=4", "--set", "env.backend=cpu"]) == 0
    runs = list((tmp_path / "runs").iterdir())
    assert len(runs) == 1
    capsys.readouterr()
    assert main(["eval", str(runs[0]), "--episodes", "1", "--json"]) == 0
    (clip,) = json.loads(capsys.readouterr().out)["clips"].values()
    ours = clip["ours"]
    assert ours["E_h_cm"]["mean"] > 0
    assert set(ours["ended_by"]) <= {"link_deviation", "root_too_low", "object_deviation", "interaction_distance",
                                     "contact_lost", "clip_end"}
    if ours["success"]["rate"] == 1.0:  # a success: no termination ended it
        assert set(ours["ended_by"]) == {"clip_end"}
    onnx = tmp_path / "teacher.onnx"
    assert main(["export", "onnx", str(runs[0]), "-o", str(onnx), "--recorded", "20"]) == 0
    capsys.readouterr()
    assert main(["export", "check", str(onnx)]) == 1
    assert "not deployable" in capsys.readouterr().out

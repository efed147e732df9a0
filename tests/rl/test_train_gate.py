"""`robot-hoi train` refuses a reference that fails the physics gate, and trains it with --skip-gate."""

from __future__ import annotations

import pytest

from robot_hoi.cli import main
from robot_hoi.tasks.interaction import feasibility

TINY = ["--budget", "1it", "--eval-episodes", "1", "--set", "env.num_envs=4", "--set", "ppo.horizon=4",
        "--set", "env.backend=cpu"]
FAILED = {"verdict": "FAIL", "segments": [{"hand": "left", "frames": [40, 90]}], "start_frame": 30, "frames": 25,
          "frames_total": 198, "frames_held": 15,
          "failure": {"frame": 55, "reason": "contact_lost", "hand": "left", "segment": "left 40-90",
                      "object_error_cm": 4.2}}


def test_a_failing_reference_is_refused_with_the_reason(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(feasibility, "physics_gate", lambda clip, *a, **k: calls.append(clip.name) or FAILED)
    assert main(["train", "--data", "embedded:lift_place", "--out", str(tmp_path / "run"), *TINY]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert "contact_lost at frame 55 in held segment left 40-90" in err and "--skip-gate" in err
    assert len(calls) == 1
    # the retarget went where the teacher reads its reference: a run after the refusal does not retarget again
    assert len(list((tmp_path / "run").rglob("references/*.npz"))) == 1
    assert not list((tmp_path / "run").rglob("*.pt"))


@pytest.mark.slow
def test_skip_gate_trains_anyway(tmp_path, monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("--skip-gate must not run the gate")

    monkeypatch.setattr(feasibility, "physics_gate", never)
    assert main(["train", "--data", "embedded:lift_place", "--out", str(tmp_path / "run"), "--skip-gate",
                 *TINY]) == 0
    assert list((tmp_path / "run").rglob("*.pt"))

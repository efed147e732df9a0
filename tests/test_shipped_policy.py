"""The student shipped in policies/: its ONNX follows today's deploy contract, it completes the interaction in
sim2sim (validation physics, self-collision on, simulated Inspire hands over serial bytes), and the robot runtime
runs it in a dry run without faults."""

from __future__ import annotations

import json

import pytest

from robot_hoi.paths import POLICIES_DIR

SHIPPED = POLICIES_DIR / "lift_place_student.onnx"

pytestmark = pytest.mark.skipif(not SHIPPED.is_file(), reason="no shipped student in policies/")


def test_shipped_student_meets_the_contract_and_carries_its_reference():
    from robot_hoi.cli import main

    assert SHIPPED.with_name("lift_place_student.motion.npz").is_file()
    assert main(["export", "check", str(SHIPPED), "--embodiment", "g1_inspire"]) == 0


def test_shipped_student_lifts_the_box_in_sim2sim(tmp_path):
    from robot_hoi.cli import main

    out = tmp_path / "report"
    assert main(["sim2sim", "--policy", str(SHIPPED), "--suite", "nominal", "--episodes", "1", "--videos", "0",
                 "-q", "-o", str(out)]) == 0
    cell = json.loads((out / "metrics.json").read_text())["cells"][0]
    assert cell["success_rate"] == 1.0 and cell["interaction_success_rate"] == 1.0


def test_shipped_student_runs_on_the_dry_run_robot(tmp_path):
    from deploy.cli import main as deploy_main

    code = deploy_main(["--dry-run", "--policy", str(SHIPPED), "--hand-bus", "serial", "--duration", "5",
                        "--log-dir", str(tmp_path), "--zero-torque-s", "0.1", "--ramp-s", "0.5", "--damp-s", "0.2",
                        "--auto-start", "--max-input-age-periods", "10", "--max-overruns", "1000",
                        "--min-hand-rate-share", "0.2", "--status", "plain"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert code == 0 and summary["faults"] == [] and summary["policy_steps"] >= 100

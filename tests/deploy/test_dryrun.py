"""`robot-hoi deploy --dry-run` end to end on each hand transport, the hands-bench mode, and CLI errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from deploy.cli import main as deploy_main
from deploy.contract import PolicyContract
from deploy.runlog import load_events, load_ticks
from deploy.safety import Phase

# Staleness is tested on the fake clock; a generous limit keeps these real-time runs stable on a busy machine.
# Overruns and the hand rate are tested on the fake clock too; here only a grossly broken run may trip them.
FAST = ["--zero-torque-s", "0.1", "--ramp-s", "0.3", "--damp-s", "0.2", "--auto-start", "--max-input-age-periods", "10",
        "--hand-timeout", "0.1", "--max-overruns", "1000", "--max-stall-periods", "30", "--watchdog-s", "2",
        "--min-hand-rate-share", "0.2", "--status", "plain"]


def check_run(log_dir, contract: PolicyContract, min_policy_steps: int):
    summary = json.loads((log_dir / "summary.json").read_text())
    assert summary["faults"] == [], summary["faults"]
    assert summary["policy_steps"] >= min_policy_steps
    assert summary["exit_reason"].startswith("duration reached")
    phases = [e["to"] for e in load_events(log_dir) if e["event"] == "phase"]
    assert phases == ["ZERO_TORQUE", "RAMP_TO_DEFAULT", "HOLD", "POLICY", "DAMP"]
    ticks = load_ticks(log_dir)
    assert len(ticks["t"]) == summary["ticks"]
    sent = ~np.isnan(ticks["cmd_q"][:, 0])
    q = ticks["cmd_q"][sent]
    assert np.all(q >= contract.joint_lower[:29]) and np.all(q <= contract.joint_upper[:29])
    units = ticks["cmd_hand_units"]
    assert np.all((units == -1) | ((units >= 0) & (units <= 1000)))
    policy = ticks["phase"] == int(Phase.POLICY)
    assert np.all(np.diff(ticks["policy_tick"][policy]) >= 1)
    # the simulated fingers really moved toward the commanded grasp (units fall from open toward 300)
    assert ticks["hand_angles"][policy][-1, :4].max() < 950
    return summary, ticks


@pytest.mark.parametrize("transport", ["serial", "modbus", "can"])
def test_dry_run_end_to_end(dev_policy, tmp_path, transport):
    contract = PolicyContract.from_onnx(dev_policy)
    code = deploy_main(["--dry-run", "--policy", str(dev_policy), "--hand-bus", transport, "--duration", "3.0",
                        "--log-dir", str(tmp_path), *FAST])
    assert code == 0
    summary, _ = check_run(tmp_path, contract, min_policy_steps=40)
    assert summary["setup"]["hands"] == f"{transport} (simulated devices)"
    # one hand cycle per tick when the machine is quiet; a starved thread (a training beside the tests) lags a tenth
    assert summary["hands"]["left"]["cycles"] >= summary["ticks"] // 2


def test_a_policy_without_tracked_poses_runs_with_no_tracker(tmp_path):
    """An object-free, mocap-free policy (proprioception + reference joints + the reference's own pelvis path): the
    dry run opens no tracker, starts without one and runs the policy fault-free."""
    from deploy.devpolicy import build_dev_policy

    from .conftest import EMBODIMENT_YAML

    terms = ["projected_gravity", "base_ang_vel", "joint_pos", "joint_vel", "hand_force", "last_action",
             "ref_joint_pos", "ref_root_local"]
    policy = build_dev_policy(tmp_path / "free.onnx", embodiment=EMBODIMENT_YAML, obs_terms=terms)
    contract = PolicyContract.from_onnx(policy)
    assert not contract.needs_tracker
    log_dir = tmp_path / "log"
    assert deploy_main(["--dry-run", "--policy", str(policy), "--duration", "3.0", "--log-dir", str(log_dir),
                        *FAST]) == 0
    summary, ticks = check_run(log_dir, contract, min_policy_steps=40)
    assert summary["setup"]["tracker"] == "none (the policy reads no tracked pose)"
    assert np.isinf(ticks["tracker_age"]).all()  # no pose ever arrived, and none was needed


def test_robot_hoi_cli_runs_the_dry_run(dev_policy, tmp_path, capsys):
    from robot_hoi.cli import main

    code = main(["deploy", "--dry-run", "--policy", str(dev_policy), "--duration", "2.0", "--rate", "50",
                 "--log-dir", str(tmp_path), *FAST])
    out = capsys.readouterr().out
    assert code == 0
    assert "period error" in out and "50.0 Hz" in out and str(tmp_path / "summary.json") in out


def test_hands_bench_uses_the_given_ports(dev_policy, tmp_path):
    from deploy.hands.simulated import start_simulated_hand

    sims = [start_simulated_hand("serial", side) for side in ("left", "right")]
    try:
        code = deploy_main(["--dry-run", "--policy", str(dev_policy), "--hand-bus", "serial", "--hand-port",
                            sims[0].port, sims[1].port, "--duration", "2.5", "--log-dir", str(tmp_path), *FAST])
        assert code == 0
        summary = json.loads((tmp_path / "summary.json").read_text())
        assert summary["setup"]["hands"] == "serial (real ports)"
        assert sum(1 for w in sims[0].writes if w.register == "ANGLE_SET") > 10
        assert sims[1].model.commanded_angles.max() < 1000  # the policy's grasp reached the device
    finally:
        for sim in sims:
            sim.stop()


@pytest.mark.parametrize("argv,expected", [
    (["--policy", "missing.onnx", "--dry-run"], "missing.onnx: policy file not found"),
    (["--policy", "{policy}"], "a real run needs the hands"),
    (["--policy", "{policy}", "--dry-run", "--hand-port", "/dev/a", "/dev/b", "--hand-bus", "can"],
     "--hand-bus can uses --can-channel"),
    (["--policy", "{policy}", "--rate", "50", "--hand-port", "/dev/a", "/dev/b", "--body", "sim"],
     "only a dry run"),
    (["--policy", "{policy}", "--dry-run", "--embodiment", "{yaml}"], "does not match"),
    (["--policy", "{policy}", "--dry-run", "--hand-port", "/dev/does-not-exist-a", "/dev/does-not-exist-b"],
     "cannot open"),
    (["--policy", "{policy}", "--dry-run", "--hand-bus", "can", "--can-channel", "nobody-here",
      "--can-interface", "virtual", "--hand-timeout", "0.01"], "the hands did not come up"),
])
def test_cli_errors_are_one_line(dev_policy, tmp_path, capsys, argv, expected):
    from robot_hoi.cli import main

    yaml_path = tmp_path / "other.yaml"
    from .conftest import EMBODIMENT_YAML

    yaml_path.write_text(EMBODIMENT_YAML.read_text().replace("control_dt: 0.0333333333333", "control_dt: 0.02"))
    argv = [a.format(policy=dev_policy, yaml=yaml_path) for a in argv]
    code = main(["deploy", *argv, "--log-dir", str(tmp_path / "log")])
    err = capsys.readouterr().err
    assert code == 2
    assert expected in err and err.count("\n") == 1 and "Traceback" not in err


def test_sigint_damps_then_exits_cleanly(dev_policy, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    from .conftest import REPO

    proc = subprocess.Popen(
        [sys.executable, "-m", "deploy", "--dry-run", "--policy", str(dev_policy), "--duration", "60",
         "--log-dir", str(tmp_path), "--hand-bus", "can", *FAST],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        events = tmp_path / "events.jsonl"
        while time.monotonic() < deadline:
            if events.is_file() and '"to": "POLICY"' in events.read_text():
                break
            time.sleep(0.05)
        else:
            raise AssertionError("the dry run never reached POLICY")
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    damp = [e for e in load_events(tmp_path) if e["event"] == "phase" and e["to"] == "DAMP"]
    assert damp and damp[0]["reason"] == "SIGINT"
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["exit_reason"].startswith("SIGINT") and summary["faults"] == []
    assert "SIGINT" in out


def test_real_run_without_cyclonedds_says_how_to_install(dev_policy, tmp_path, capsys, monkeypatch):
    import deploy.body.unitree_dds as dds
    from robot_hoi.cli import main

    monkeypatch.setattr(dds, "cyclonedds_available", lambda: False)
    code = main(["deploy", "--policy", str(dev_policy), "--hand-port", "/dev/a", "/dev/b",
                 "--log-dir", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and "pip install 'cyclonedds==11.0.1'" in err and err.count("\n") == 1

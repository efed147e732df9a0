"""The command line as a field engineer meets it: every signal damps and leaves a summary with an exit code that
says why, a real body never leaves ZERO_TORQUE without the operator, --auto-start only in simulation, the
start-up hand bus budget, and the live status for the operator."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from deploy.cli import main as deploy_main
from deploy.runlog import load_events

from .conftest import REPO
from .test_dryrun import FAST


def start_dry_run(dev_policy, log_dir, *extra):
    return subprocess.Popen(
        [sys.executable, "-m", "deploy", "--dry-run", "--policy", str(dev_policy), "--duration", "60",
         "--log-dir", str(log_dir), "--hand-bus", "can", *FAST, *extra],
        cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_event(log_dir, text, timeout=40.0):
    events = log_dir / "events.jsonl"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if events.is_file() and text in events.read_text():
            return
        time.sleep(0.05)
    raise AssertionError(f"{text} never appeared in {events}")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_damp_write_the_summary_and_name_the_signal(dev_policy, tmp_path, signum):
    proc = start_dry_run(dev_policy, tmp_path)
    try:
        wait_for_event(tmp_path, '"to": "POLICY"')
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum, err
    assert "Traceback" not in err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["final_phase"] == "DAMP" and summary["outcome"] == name and summary["exit_code"] == 128 + signum
    assert summary["exit_reason"].startswith(name) and summary["faults"] == []
    damp = [e for e in load_events(tmp_path) if e["event"] == "phase" and e["to"] == "DAMP"]
    assert damp[0]["reason"] == name


def test_double_ctrl_c_exits_130_with_a_reason(dev_policy, tmp_path):
    proc = start_dry_run(dev_policy, tmp_path, "--damp-s", "30")
    try:
        wait_for_event(tmp_path, '"to": "POLICY"')
        proc.send_signal(signal.SIGINT)
        wait_for_event(tmp_path, '"to": "DAMP"')
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["exit_reason"] == "SIGINT twice: aborted after one damping command"
    assert summary["phase_time_s"]["DAMP"] < 10


def test_real_body_stays_limp_until_the_operator_confirms(dev_policy, tmp_path):
    """Not a dry run: a DDS robot (simulated here, on lo) and hands on their ports. Nothing but zero torque
    reaches the robot until Enter is pressed; then it ramps, and waits again in HOLD."""
    pytest.importorskip("cyclonedds")
    from deploy.body.dds_loopback import DdsLoopbackRobot
    from deploy.hands.simulated import start_simulated_hand

    domain = 150 + os.getpid() % 50
    robot = DdsLoopbackRobot(domain, "lo").start()
    sims = [start_simulated_hand("serial", side) for side in ("left", "right")]
    proc = subprocess.Popen(
        [sys.executable, "-m", "deploy", "--policy", str(dev_policy), "--dds-interface", "lo", "--dds-domain",
         str(domain), "--tracker", "sim", "--hand-port", sims[0].port, sims[1].port, "--duration", "60",
         "--log-dir", str(tmp_path), "--zero-torque-s", "0.1", "--ramp-s", "0.3", "--damp-s", "0.2",
         "--max-input-age-periods", "30", "--hand-timeout", "0.1", "--max-overruns", "1000", "--max-stall-periods",
         "30", "--watchdog-s", "2", "--min-hand-rate-share", "0.2", "--status", "plain"],
        cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_event(tmp_path, '"to": "ZERO_TORQUE"')
        limp_kp = []
        for _ in range(30):  # 1.5 s after zero_torque_s ended: still limp
            time.sleep(0.05)
            if robot.last_command is not None:
                limp_kp.append(float(np.max(robot.last_command.kp)))
        assert limp_kp and max(limp_kp) == 0.0
        proc.stdin.write("\n")
        proc.stdin.flush()
        wait_for_event(tmp_path, '"to": "HOLD"')
        out, err = proc.communicate("q\n", timeout=30)  # the operator stops it in HOLD
    finally:
        proc.kill()
        robot.stop()
        for sim in sims:
            sim.stop()
    assert proc.returncode == 3, err  # the policy never ran: stopped in HOLD
    phases = [e["to"] for e in load_events(tmp_path) if e["event"] == "phase"]
    assert phases == ["ZERO_TORQUE", "RAMP_TO_DEFAULT", "HOLD", "DAMP"]
    assert ">>> robot limp (zero torque): press Enter" in err and ">>> HOLD reached: press Enter" in err


@pytest.mark.parametrize("argv,expected", [
    (["--auto-start", "--hand-port", "/dev/a", "/dev/b"], "--auto-start is only for dry runs and simulation"),
    (["--auto-start-on", "lo", "--dds-interface", "eth0", "--hand-port", "/dev/a", "/dev/b"],
     "--auto-start-on lo is for a DDS simulator on that interface"),
    (["--dry-run", "--rate", "200"], "the hand bus is too slow for this loop"),
])
def test_refusals_before_anything_opens(dev_policy, tmp_path, capsys, argv, expected):
    code = deploy_main(["--policy", str(dev_policy), "--log-dir", str(tmp_path), *argv])
    err = capsys.readouterr().err
    assert code == 2 and expected in err and err.count("\n") == 1


def test_hand_rate_lowered_when_the_bus_cannot_keep_up(dev_policy, tmp_path):
    code = deploy_main(["--dry-run", "--policy", str(dev_policy), "--rate", "100", "--duration", "2.5",
                        "--log-dir", str(tmp_path), *FAST, "--max-input-age-periods", "30",  # 10 ms periods
                        "--min-hand-rate-share", "0.05"])  # a 100 Hz loop on a loaded CI box: the plan is tested
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert code == 0, summary["faults"]
    assert summary["hand_rate_hz"] == pytest.approx(50.0)
    assert "hands exchanged every 2 ticks (50.0 Hz)" in summary["setup"]["hand_budget"]


def test_plain_status_lines_and_prompts(dev_policy):
    from deploy.operator import ScriptedOperator
    from deploy.safety import SafetyConfig
    from deploy.status import PlainStatus, make_status_view

    from .conftest import RuntimeRig

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=None,
                                                     damp_s=0.2))
    rig.runtime.operator = ScriptedOperator(rig.clock, [(1000.5, "start"), (1001.5, "start")])
    stream = io.StringIO()
    rig.runtime.status = make_status_view("auto", stream)  # not a terminal: plain lines
    assert isinstance(rig.runtime.status, PlainStatus)
    rig.runtime.run(duration_s=3.0)
    text = stream.getvalue()
    assert ">>> robot limp (zero torque): press Enter or hold remote L1+A to stiffen" in text
    assert ">>> HOLD reached: press Enter or hold remote L1+A to start the policy" in text
    assert "POLICY" in text and "| hands L 30.0 R 30.0 Hz | faults none" in text


def test_rich_status_on_a_terminal(dev_policy):
    import pty

    from deploy.status import RichStatus, make_status_view

    from .conftest import RuntimeRig

    master, slave = pty.openpty()
    with os.fdopen(slave, "w") as terminal:
        view = make_status_view("auto", terminal)
        assert isinstance(view, RichStatus)
        rig = RuntimeRig(dev_policy)
        rig.runtime.status = view
        rig.runtime.run(duration_s=1.5)
        view.close()
        os.set_blocking(master, False)
        shown = os.read(master, 1 << 16).decode(errors="replace")
    os.close(master)
    assert "HOLD" in shown and "POLICY" in shown and "faults none" in shown


@pytest.mark.slow
def test_slcan_stream_garbled_mid_policy_damps_with_a_summary_not_a_traceback(dev_policy, tmp_path, capsys):
    """Both hands behind one emulated slcan USB adapter (hands bench: real ports, body simulated)."""
    from deploy.hands.sim_slcan import SimulatedSlcanAdapter
    from deploy.hands.simulated import start_simulated_hand

    left = start_simulated_hand("can", "left", hand_id=1)
    right = start_simulated_hand("can", "right", hand_id=2, channel=left.channel)
    adapter = SimulatedSlcanAdapter(left.channel)
    events = tmp_path / "events.jsonl"
    try:
        import threading

        def garble_once_policy_runs():
            deadline = time.monotonic() + 40
            while time.monotonic() < deadline and not (events.is_file() and '"to": "POLICY"' in events.read_text()):
                time.sleep(0.05)
            adapter.garble_next(10_000)

        threading.Thread(target=garble_once_policy_runs, daemon=True).start()
        code = deploy_main(["--dry-run", "--policy", str(dev_policy), "--hand-bus", "can", "--can-interface",
                            "slcan", "--can-channel", adapter.port, "--duration", "30", "--log-dir", str(tmp_path),
                            *FAST, "--hand-timeout", "0.3", "--hand-retries", "4", "--max-input-age-periods", "30"])
    finally:
        adapter.stop()
        left.stop()
        right.stop()
    err = capsys.readouterr().err
    assert "Traceback" not in err and code != 2, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert code == 1 and summary["outcome"] == "FAULT" and summary["policy_steps"] > 0, summary["faults"]
    assert summary["final_phase"] == "DAMP" and any("hand" in f for f in summary["faults"]), summary["faults"]

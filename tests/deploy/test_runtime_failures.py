"""When the runtime itself fails, on the fake clock with the simulated body and hands: a full log disk, a dead
terminal, a refused start, a stall, a widened policy file, a fumbled remote, lost hand replies. In each the last
command is a damping command (or nothing stiff where no policy ran) and the outcome is the documented one."""

from __future__ import annotations

import errno
import io
import os
from pathlib import Path

import numpy as np
import pytest

from deploy.runlog import EventLog, TickRecorder, load_events, load_ticks
from deploy.safety import Phase, SafetyConfig

from .conftest import RuntimeRig

FAST = dict(zero_torque_s=0.1, ramp_s=0.3, auto_start_after_s=0.1, damp_s=0.2)


def damping_commands(rig) -> list[dict]:
    """The trailing run of damping commands (kp 0, kd damp_kd) the body received."""
    out = []
    for command in reversed(rig.body.commands):
        if not (np.all(command["kp"] == 0) and np.all(command["kd"] == rig.safety.damp_kd)):
            break
        out.append(command)
    return out


def assert_ends_damped(rig, summary, outcome: str, code: int):
    assert summary["outcome"] == outcome and summary["exit_code"] == code, summary["exit_reason"]
    assert summary["final_phase"] == "DAMP"
    assert len(damping_commands(rig)) >= round(rig.safety.damp_s / rig.dt) - 1, "damped for damp_s"


class FullDisk(io.TextIOBase):
    """A file on a disk that filled up: every write raises ENOSPC."""

    def write(self, text):
        raise OSError(errno.ENOSPC, "No space left on device")

    def flush(self):
        raise OSError(errno.ENOSPC, "No space left on device")


class AfterSteps:
    """Wraps the policy: after `n` steps, run `action` once (a fault arriving mid-run)."""

    def __init__(self, inner, n: int, action):
        self.inner, self.n, self.action, self.calls = inner, n, action, 0

    def __call__(self, obs):
        self.calls += 1
        if self.calls == self.n:
            self.action()
        return self.inner(obs)


# ------------------------------------------------------------------ 1. logging never stands between a fault and damping
def test_disk_full_during_policy_still_damps_and_reports_what_was_lost(dev_policy, tmp_path, monkeypatch):
    rig = RuntimeRig(dev_policy, log_dir=tmp_path, safety=SafetyConfig(**FAST))

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    def disk_fills_and_a_hand_faults():
        rig.events._file = FullDisk()
        monkeypatch.setattr("deploy.runlog.atomic_write_bytes", no_space)
        rig.right.error_bits[1] = 1  # locked rotor: a fault that must damp while nothing can be logged

    rig.runtime.policy = AfterSteps(rig.policy, 20, disk_fills_and_a_hand_faults)
    summary = rig.runtime.run(duration_s=10.0)
    assert_ends_damped(rig, summary, "FAULT", 1)
    assert "right hand fault" in summary["faults"][0]
    logs = summary["logs"]
    assert logs["events"]["errors"] > 0 and logs["events"]["lost"] > 0
    assert "No space left on device" in logs["events"]["last_error"]
    assert logs["ticks"]["errors"] > 0 and logs["ticks"]["lost"] > 0
    assert "No space left on device" in logs["ticks"]["last_error"]
    assert len(rig.events.of_kind("fault")) == 1  # still kept in memory for the summary


def test_crash_sends_damping_before_anything_is_logged(dev_policy, tmp_path):
    rig = RuntimeRig(dev_policy, log_dir=tmp_path, safety=SafetyConfig(**FAST))

    def disk_full_then_a_bug():
        rig.events._file = FullDisk()
        rig.events.log = lambda *a, **k: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left on device"))
        raise ZeroDivisionError("a bug in the loop")

    rig.runtime.policy = AfterSteps(rig.policy, 10, disk_full_then_a_bug)
    with pytest.raises(ZeroDivisionError):
        rig.runtime.run(duration_s=10.0)
    last = rig.body.commands[-1]
    assert np.all(last["kp"] == 0) and np.all(last["kd"] == rig.safety.damp_kd)
    assert rig.runtime.exit_reason.startswith("crashed: ZeroDivisionError")


def test_tick_writer_survives_a_failed_write_and_says_what_it_lost(tmp_path, monkeypatch):
    from deploy import runlog

    recorder = TickRecorder(tmp_path, chunk_ticks=10)
    real = runlog.atomic_write_bytes
    failed = []

    def first_write_fails(path, data, **kwargs):
        if not failed and str(path).startswith(str(tmp_path)):  # other tests' writers may still be finishing
            failed.append(path)
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, data, **kwargs)

    monkeypatch.setattr(runlog, "atomic_write_bytes", first_write_fails)
    for i in range(30):
        recorder.record({"t": float(i) * 0.01, "x": np.array([i])})
    recorder.close()
    assert recorder.report() == {"errors": 1, "lost": 10, "last_error": "[Errno 28] No space left on device"}
    assert load_ticks(tmp_path)["x"][:, 0].tolist() == list(range(10, 30))


def test_logs_reach_the_disk_every_second_and_are_synced_at_phase_changes(dev_policy, tmp_path, monkeypatch):
    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(fd), real_fsync(fd))[1])
    rig = RuntimeRig(dev_policy, log_dir=tmp_path, safety=SafetyConfig(**FAST))
    rig.run_until(Phase.POLICY)
    rig.step(int(1.5 / rig.dt))
    rig.events.wait_idle(5.0)
    rig.recorder.wait_idle(5.0)
    ticks = load_ticks(tmp_path)
    assert len(ticks["t"]) >= rig.runtime.ticks - int(1.0 / rig.dt) - 1  # at most a second only in memory
    on_disk = [e["event"] for e in load_events(tmp_path)]
    assert on_disk.count("phase") == 4  # ZERO_TORQUE, RAMP_TO_DEFAULT, HOLD, POLICY: each synced as it happened
    assert len(synced) >= 2 * 4  # events and ticks at each phase change


def test_event_log_never_raises_into_the_loop(tmp_path):
    from deploy.clock import FakeClock

    events = EventLog(FakeClock(), tmp_path / "events.jsonl")
    events._file = FullDisk()
    events.log("fault", reason="x")
    events.sync()
    events.close()
    assert events.report()["errors"] >= 1 and events.report()["lost"] == 1
    assert events.of_kind("fault")[0]["reason"] == "x"


def test_unwritable_log_dir_is_a_usage_error_at_start(dev_policy, tmp_path, capsys):
    from deploy.cli import main

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    code = main(["--dry-run", "--policy", str(dev_policy), "--log-dir", str(blocker / "logs"), "--auto-start"])
    err = capsys.readouterr().err
    assert code == 2 and "--log-dir" in err and "not writable" in err and "Traceback" not in err, err


def test_summary_write_failure_is_one_line_not_a_crash(dev_policy, tmp_path, capsys, monkeypatch):
    from deploy import session

    monkeypatch.setattr(session, "atomic_write_text",
                        lambda *a, **k: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left on device")))
    from deploy.cli import main

    code = main(["--dry-run", "--policy", str(dev_policy), "--log-dir", str(tmp_path), "--duration", "1.5",
                 "--zero-torque-s", "0.1", "--ramp-s", "0.3", "--damp-s", "0.2", "--auto-start",
                 "--max-input-age-periods", "10", "--hand-timeout", "0.1", "--max-overruns", "1000",
                 "--min-hand-rate-share", "0.2", "--status", "off"])
    err = capsys.readouterr().err
    assert code == 0 and "summary.json not written" in err and "Traceback" not in err, err
    assert not (tmp_path / "summary.json").exists()


# ------------------------------------------------------------------ 2. a start is one fresh press while every input is usable
def test_refused_start_disarms_and_says_why(dev_policy):
    from deploy.operator import ScriptedOperator
    from deploy.status import status_text

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**{**FAST, "auto_start_after_s": None}))
    rig.runtime.operator = ScriptedOperator(rig.clock, [(rig.clock.now() + 0.3, "start")])  # stiffen
    rig.run_until(Phase.HOLD)
    rig.tracker.drop("object")
    rig.step(3)  # stale now
    rig.runtime.operator = ScriptedOperator(rig.clock, [(rig.clock.now(), "start")])
    rig.step(3)
    assert rig.runtime.phase == Phase.HOLD
    assert "object pose stale" in rig.events.of_kind("start_refused")[0]["reason"]
    assert "start refused: object pose stale" in status_text(rig.runtime)
    assert rig.runtime.prompt is not None  # asked again
    rig.tracker.restore("object")
    rig.step(30)
    assert rig.runtime.phase == Phase.HOLD, "a refused press must not fire later by itself"
    rig.runtime.operator = ScriptedOperator(rig.clock, [(rig.clock.now(), "start")])
    rig.step(2)
    assert rig.runtime.phase == Phase.POLICY
    assert rig.events.of_kind("phase")[-1]["reason"] == "operator start"
    assert "start refused" not in status_text(rig.runtime)


# ------------------------------------------------------------------ 3. automatic start only against a simulator
def test_auto_start_on_a_robot_interface_is_refused(dev_policy, tmp_path, capsys):
    from deploy.cli import main

    code = main(["--policy", str(dev_policy), "--log-dir", str(tmp_path), "--auto-start-on", "eth0",
                 "--dds-interface", "eth0", "--hand-port", "/dev/a", "/dev/b"])
    err = capsys.readouterr().err
    assert code == 2 and "eth0 is not a loopback interface" in err and err.count("\n") == 1, err


def test_only_loopback_interfaces_count_as_a_simulator():
    from deploy.session import is_loopback_interface

    assert is_loopback_interface("lo")
    assert not is_loopback_interface("eth0") and not is_loopback_interface("no-such-if0")


# ------------------------------------------------------------------ 4. a stalled loop: the stall bound, the reference clock, the watchdog
class Stall:
    """Wraps the policy: at step `at`, the process stalls for `seconds` (fake time, and real time if `real`)."""

    def __init__(self, rig, at: int, seconds: float, real: bool = False):
        self.rig, self.at, self.seconds, self.real = rig, at, seconds, real
        self.inner = rig.policy
        self.calls = 0
        self.ticks: list[int] = []
        self.commands_when_resumed: int | None = None

    def __call__(self, obs):
        import time

        self.calls += 1
        self.ticks.append(self.rig.runtime.policy_tick)
        if self.calls == self.at:
            if self.real:
                time.sleep(self.seconds)
            self.rig.clock.advance(self.seconds)
            self.commands_when_resumed = len(self.rig.body.commands)
        return self.inner(obs)


def test_a_half_second_stall_in_policy_damps(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**FAST))
    rig.runtime.policy = Stall(rig, 20, 0.5)
    summary = rig.runtime.run(duration_s=10.0)
    assert_ends_damped(rig, summary, "FAULT", 1)
    assert summary["faults"][0].startswith("loop stalled") and "limit 66.7 ms (2 periods)" in summary["faults"][0]
    assert summary["overruns"] == 1


def test_the_reference_clock_does_not_jump_after_a_late_tick(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**FAST))
    stall = Stall(rig, 20, 1.5 * rig.dt)  # one deadline missed: under the stall bound, the policy goes on
    rig.runtime.policy = stall
    summary = rig.runtime.run(duration_s=3.0)
    assert summary["outcome"] == "COMPLETED" and summary["missed_deadlines"] >= 1
    assert stall.ticks == list(range(len(stall.ticks)))  # one reference frame per policy step, none skipped


@pytest.mark.slow
def test_gc_is_off_during_policy_and_restored_after(dev_policy):
    import gc

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**FAST))
    seen = []
    inner = rig.policy
    rig.runtime.policy = lambda obs: (seen.append((gc.isenabled(), gc.get_freeze_count() > 0)), inner(obs))[1]
    assert gc.isenabled()
    rig.runtime.run(duration_s=2.0)
    assert seen and all(s == (False, True) for s in seen)
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_memory_is_locked_where_allowed_and_a_refusal_is_a_note(dev_policy, monkeypatch):
    from deploy import realtime

    calls = []
    monkeypatch.setattr(realtime, "_mlockall", lambda flags: (calls.append(flags), errno.EPERM)[1])
    monkeypatch.setattr(realtime, "_munlockall", lambda: calls.append("unlock"))
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**FAST))
    rig.runtime.lock_memory = True
    summary = rig.runtime.run(duration_s=2.0)
    assert calls[0] == realtime.MCL_CURRENT | realtime.MCL_FUTURE
    assert summary["outcome"] == "COMPLETED" and summary["memory"].startswith("not locked (Operation not permitted")
    monkeypatch.setattr(realtime, "_mlockall", lambda flags: (calls.append(flags), 0)[1])
    assert realtime.lock_memory() is None


def test_watchdog_thread_damps_a_stuck_loop_before_it_resumes(dev_policy):
    from deploy.watchdog import ThreadWatchdog

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**FAST))
    rig.runtime.watchdog = ThreadWatchdog(timeout_s=0.1)
    stall = Stall(rig, 20, 0.6, real=True)  # the loop thread is stuck for 0.6 s of wall time
    rig.runtime.policy = stall
    summary = rig.runtime.run(duration_s=10.0)
    first_after_stall = rig.body.commands[stall.commands_when_resumed - 1]
    assert np.all(first_after_stall["kp"] == 0) and np.all(first_after_stall["kd"] == rig.safety.damp_kd), \
        "the watchdog damped the robot while the loop was stuck"
    later = rig.body.commands[stall.commands_when_resumed:]
    assert later and all(np.all(c["kp"] == 0) for c in later), "the loop never stiffened again after it"
    assert_ends_damped(rig, summary, "FAULT", 1)
    assert summary["faults"][0].startswith("watchdog: loop heartbeat stopped for")


def start_against_dds_robot(dev_policy, tmp_path, *extra):
    """A non-dry run (the DDS body, hands on their ports) against a simulated G1 on lo in this process, started
    automatically (a loopback interface): what the robot's computer runs, with the robot simulated."""
    import subprocess
    import sys

    pytest.importorskip("cyclonedds")
    from deploy.body.dds_loopback import DdsLoopbackRobot
    from deploy.hands.simulated import start_simulated_hand

    from .conftest import REPO

    domain = 100 + os.getpid() % 50  # DDS maps domain ids to UDP ports: above ~230 they overflow
    robot = DdsLoopbackRobot(domain, "lo").start()
    sims = [start_simulated_hand("serial", side) for side in ("left", "right")]
    proc = subprocess.Popen(
        [sys.executable, "-m", "deploy", "--policy", str(dev_policy), "--dds-interface", "lo", "--dds-domain",
         str(domain), "--auto-start-on", "lo", "--tracker", "sim", "--hand-port", sims[0].port, sims[1].port,
         "--duration", "60", "--log-dir", str(tmp_path), "--zero-torque-s", "0.1", "--ramp-s", "0.3",
         "--max-input-age-periods", "30", "--hand-timeout", "0.1", "--max-overruns", "1000",
         "--max-stall-periods", "30", "--min-hand-rate-share", "0.2", "--status", "plain", *extra],
        cwd=REPO, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def cleanup():
        proc.kill()
        proc.wait()
        robot.stop()
        for sim in sims:
            sim.stop()

    return proc, robot, cleanup


def wait_until(predicate, timeout_s: float) -> bool:
    import time

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def is_damping(frame, kd: float = 8.0) -> bool:
    return frame is not None and float(np.max(frame.kp[:29])) == 0.0 and np.allclose(frame.kd[:29], kd)


def wait_for_policy(tmp_path, proc):
    events = tmp_path / "events.jsonl"
    assert wait_until(lambda: events.is_file() and '"to": "POLICY"' in events.read_text() or proc.poll() is not None,
                      60.0), "never reached POLICY"
    assert proc.poll() is None, proc.communicate()[1][-3000:]


def test_sigkill_of_the_runtime_ends_damped_by_the_watchdog_process(dev_policy, tmp_path):
    import signal

    proc, robot, cleanup = start_against_dds_robot(dev_policy, tmp_path, "--watchdog-s", "1.0", "--damp-s", "0.5")
    try:
        wait_for_policy(tmp_path, proc)
        assert wait_until(lambda: robot.last_command is not None and float(np.max(robot.last_command.kp)) > 0, 5.0)
        received = robot.commands_received
        proc.send_signal(signal.SIGKILL)  # no handler, no finally: only the watchdog process is left
        proc.wait()
        assert wait_until(lambda: robot.commands_received > received and is_damping(robot.last_command), 10.0), \
            "the robot kept its last stiff command"
    finally:
        cleanup()


def test_a_frozen_runtime_is_damped_by_the_watchdog_process_and_then_faults(dev_policy, tmp_path):
    import json
    import signal
    import time

    proc, robot, cleanup = start_against_dds_robot(dev_policy, tmp_path, "--watchdog-s", "0.5", "--damp-s", "0.5")
    try:
        wait_for_policy(tmp_path, proc)
        proc.send_signal(signal.SIGSTOP)  # the whole runtime stalls (an unscheduled process, a swap storm)
        try:
            assert wait_until(lambda: is_damping(robot.last_command), 10.0), "nobody damped the stalled robot"
        finally:
            time.sleep(0.2)
            proc.send_signal(signal.SIGCONT)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 1, err[-3000:]
        summary = json.loads((tmp_path / "summary.json").read_text())
        assert summary["outcome"] == "FAULT" and summary["final_phase"] == "DAMP"
        assert any(f.startswith("watchdog: loop heartbeat stopped") or f.startswith("loop stalled")
                   for f in summary["faults"]), summary["faults"]
        assert is_damping(robot.last_command)
    finally:
        cleanup()


# ------------------------------------------------------------------ 5. a terminal that is gone costs the status line, nothing else
class DeadTerminal(io.StringIO):
    """stderr of a dropped SSH session: every write after the hang-up raises EIO."""

    def __init__(self):
        super().__init__()
        self.gone = False

    def write(self, text):
        if self.gone:
            raise OSError(errno.EIO, "Input/output error")
        return super().write(text)

    def isatty(self):
        return False


def test_sighup_with_a_dead_terminal_damps_fully_and_exits_129(dev_policy):
    import signal

    from deploy.status import PlainStatus

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**{**FAST, "damp_s": 1.0}))
    terminal = DeadTerminal()
    rig.runtime.status = PlainStatus(terminal, plain_every_s=0.0)

    def ssh_drops():
        terminal.gone = True
        rig.runtime.request_signal(signal.SIGHUP)

    rig.runtime.policy = AfterSteps(rig.policy, 20, ssh_drops)
    summary = rig.runtime.run(duration_s=10.0)
    assert_ends_damped(rig, summary, "SIGHUP", 129)
    assert len(damping_commands(rig)) >= 30
    assert summary["logs"]["status_errors"] > 0


def test_sighup_after_the_terminal_closed_exits_129_with_a_summary(dev_policy, tmp_path):
    """The real thing: stdout and stderr on a pseudo-terminal whose other end closes (the SSH session drops)."""
    import json
    import pty
    import signal
    import subprocess
    import sys

    from .conftest import REPO
    from .test_dryrun import FAST as CLI_FAST

    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "deploy", "--dry-run", "--policy", str(dev_policy), "--duration", "60",
         "--log-dir", str(tmp_path), *[a for a in CLI_FAST if a not in ("--status", "plain")], "--damp-s", "1.0"],
        cwd=REPO, stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, start_new_session=True)
    os.close(slave)
    try:
        events = tmp_path / "events.jsonl"
        assert wait_until(lambda: events.is_file() and '"to": "POLICY"' in events.read_text(), 60.0)
        os.set_blocking(master, False)
        os.close(master)  # the terminal is gone: writes to it now fail with EIO
        proc.send_signal(signal.SIGHUP)
        assert proc.wait(timeout=60) == 129
    finally:
        proc.kill()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["outcome"] == "SIGHUP" and summary["final_phase"] == "DAMP"
    assert summary["phase_time_s"]["DAMP"] >= 0.9


# ------------------------------------------------------------------ 7. the remote as an e-stop that cannot be fumbled
GATED = {**FAST, "auto_start_after_s": None}


def hold(rig, seconds: float, *buttons):
    from deploy.remote import keys_of

    rig.body.remote_keys = keys_of(*buttons)
    rig.step(round(seconds / rig.dt) + 1)  # seen down at the first tick and at the one `seconds` later
    rig.body.remote_keys = 0
    rig.step(2)


def test_remote_start_is_a_held_chord_not_a_single_press(dev_policy):
    from deploy.remote import START_CHORD, START_HOLD_S

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**GATED))
    rig.step(10)
    assert rig.runtime.phase == Phase.ZERO_TORQUE
    for fumble in (("A",), ("START",), ("A", "START")):
        hold(rig, 0.1, *fumble)
    hold(rig, START_HOLD_S / 2, *START_CHORD)  # the chord, let go too early
    assert rig.runtime.phase == Phase.ZERO_TORQUE
    hold(rig, START_HOLD_S + rig.dt, *START_CHORD)
    assert rig.runtime.phase == Phase.RAMP_TO_DEFAULT
    rig.run_until(Phase.HOLD)
    hold(rig, 0.1, "A")
    assert rig.runtime.phase == Phase.HOLD
    hold(rig, START_HOLD_S + rig.dt, *START_CHORD)
    assert rig.runtime.phase == Phase.POLICY


def test_remote_estop_is_one_press_debounced_and_a_second_stop_never_shortens_damping(dev_policy):
    from deploy.operator import ScriptedOperator
    from deploy.outcome import Outcome
    from deploy.remote import keys_of

    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**{**FAST, "damp_s": 1.0}))
    rig.run_until(Phase.POLICY)
    rig.step(5)
    rig.body.remote_keys = keys_of("B")  # one press: DAMP at once
    rig.step(1)
    assert rig.runtime.phase == Phase.DAMP
    damp_started = len(rig.body.commands) - 1
    for keys in (0, keys_of("B"), 0, 0, 0, keys_of("B"), 0, 0, 0, keys_of("SELECT"), 0):  # a bounce, then again
        rig.body.remote_keys = keys
        rig.step(1)
    rig.runtime.operator = ScriptedOperator(rig.clock, [(rig.clock.now(), "estop"), (rig.clock.now(), "stop")])
    while rig.step(1):
        pass
    estops = [e for e in rig.events.of_kind("operator") if e["request"] == "estop" and e["source"] == "remote"]
    assert len(estops) == 2  # the bounce (up for one sample) was not a second press
    damped = rig.body.commands[damp_started:]
    assert all(np.all(c["kp"] == 0) for c in damped)
    assert len(damped) >= round(1.0 / rig.dt), "damping ran its full --damp-s despite the extra stops"
    assert rig.runtime.outcome == Outcome.ESTOP and rig.runtime.outcome.code == 5


def test_a_silent_remote_damps_when_it_is_the_estop(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**FAST, remote_estop=True, remote_timeout_s=0.3))
    rig.run_until(Phase.POLICY)
    rig.step(5)
    rig.body.remote_connected = False  # out of range, battery flat: its last state reads as "no buttons"
    rig.step(round(0.3 / rig.dt) + 2)
    assert rig.runtime.phase == Phase.DAMP
    assert rig.runtime.fault_reasons[0].startswith("wireless remote silent for")
    summary = rig.runtime.summary()
    assert summary["outcome"] == "FAULT" and summary["exit_code"] == 1


def test_no_remote_means_no_start_when_it_is_the_estop(dev_policy):
    rig = RuntimeRig(dev_policy, safety=SafetyConfig(**FAST, remote_estop=True, wait_timeout_s=0.5))
    rig.body.remote_connected = False
    summary = rig.runtime.run(duration_s=5.0)
    assert rig.body.commands == [] and summary["outcome"] == "NOT_STARTED" and summary["exit_code"] == 3
    assert "no wireless remote" in summary["exit_reason"]


def test_remote_liveness_from_lowstate_bytes():
    from deploy.remote import remote_reporting, wireless_remote_bytes

    assert not remote_reporting(bytes(40))  # what a robot without a paired remote sends
    assert remote_reporting(wireless_remote_bytes(0))  # a paired remote, nothing pressed
    assert not remote_reporting(wireless_remote_bytes(0, live=False))


# ------------------------------------------------------------------ 6. the deploy side owns the limits
SHIPPED_STUDENT = Path(__file__).resolve().parents[2] / "policies" / "lift_place_student.onnx"


def widened(contract, **changes):
    import dataclasses

    return dataclasses.replace(contract, **changes)


def test_the_shipped_student_is_inside_the_deploy_limits():
    from deploy.contract import PolicyContract, check_against_embodiment

    from .conftest import EMBODIMENT_YAML

    if not SHIPPED_STUDENT.is_file():
        pytest.skip("no shipped student in this checkout")
    check_against_embodiment(PolicyContract.from_onnx(SHIPPED_STUDENT), EMBODIMENT_YAML)


@pytest.mark.parametrize("field,change,expected", [
    ("action_scale", lambda c: c.action_scale * 10, "action_scale left_hip_pitch_joint 6 vs 0.6 in the config"),
    ("joint_lower", lambda c: c.joint_lower - 3.0,
     "joint_lower left_hip_pitch_joint -5.5307 rad is below the config's -2.5307"),
    ("joint_upper", lambda c: c.joint_upper + 3.0,
     "joint_upper left_hip_pitch_joint 5.8798 rad is above the config's 2.8798 (and 40 more joints)"),
    ("effort_limit", lambda c: np.full_like(c.effort_limit, 1e6),
     "effort_limit left_hip_pitch_joint 1e+06 N m is above the config's 88 (and 40 more joints)"),
    ("action_offset", lambda c: c.action_offset + 0.5,
     "action_offset left_hip_pitch_joint 0.4000 rad vs -0.1000 (default pose) in the config"),
    ("action_clip", lambda c: 1e3, "action_clip 1000 is above the config's 4"),
])
def test_a_policy_file_cannot_widen_its_own_limits(dev_policy, field, change, expected):
    from deploy.contract import PolicyContract, check_against_embodiment
    from deploy.errors import ContractError

    from .conftest import EMBODIMENT_YAML

    contract = PolicyContract.from_onnx(dev_policy)
    check_against_embodiment(contract, EMBODIMENT_YAML)
    with pytest.raises(ContractError) as info:
        check_against_embodiment(widened(contract, **{field: change(contract)}), EMBODIMENT_YAML)
    assert expected in str(info.value), str(info.value)


def test_a_widened_policy_is_refused_at_start_with_a_usage_exit(dev_policy, tmp_path, capsys):
    """The issue's file: the shipped student's metadata with scale x10, limits +3 rad, effort 1e6, offsets +0.5."""
    from deploy.cli import main
    from deploy.contract import PolicyContract

    from .test_contract import write_policy

    contract = PolicyContract.from_onnx(dev_policy)
    bad = widened(contract, action_scale=contract.action_scale * 10, joint_lower=contract.joint_lower - 3.0,
                  joint_upper=contract.joint_upper + 3.0, effort_limit=np.full_like(contract.effort_limit, 1e6),
                  action_offset=contract.action_offset + 0.5, default_pose=contract.default_pose)
    path = write_policy(tmp_path / "wide.onnx", bad.to_metadata(), contract.obs_dim, contract.num_actions)
    (tmp_path / contract.reference.file).write_bytes(contract.reference_path().read_bytes())
    code = main(["--dry-run", "--policy", str(path), "--log-dir", str(tmp_path / "logs"), "--auto-start"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    for field in ("joint_lower", "joint_upper", "effort_limit", "action_scale", "action_offset"):
        assert f"{field} left_hip_pitch_joint" in err and "(and 40 more joints)" in err, err


def test_deploy_limits_are_the_models():
    """The YAML's deploy limits are the physical description training exports (robot_hoi's model)."""
    from deploy.embodiment import load_embodiment

    from .conftest import EMBODIMENT_YAML

    description = pytest.importorskip("robot_hoi.embodiment.config").robot_description("g1_inspire")
    joints = {j.name: j for j in description.joints}
    limits = load_embodiment(EMBODIMENT_YAML).limits
    for name, (lower, upper, effort) in limits.joints.items():
        assert (lower, upper, effort) == (*joints[name].range, joints[name].effort), name
    assert sorted(limits.joints) == sorted(load_embodiment(EMBODIMENT_YAML).actuator_names)


def test_training_still_reads_the_embodiment_yaml():
    config = pytest.importorskip("robot_hoi.embodiment.config")
    emb = config.load_embodiment("g1_inspire")
    assert len(emb.actuators) == 41 and emb.deploy["action_clip"] == 4.0


def dry_options(dev_policy, tmp_path, **changes):
    from deploy.session import DeployOptions

    return DeployOptions(policy=str(dev_policy), dry_run=True, log_dir=str(tmp_path / "logs"), status="off",
                         auto_start=True, **changes)


def test_hand_force_and_speed_come_from_the_embodiment_yaml(dev_policy, tmp_path):
    import yaml

    from deploy.session import Session

    from .conftest import EMBODIMENT_YAML

    raw = yaml.safe_load(EMBODIMENT_YAML.read_text())
    raw["deploy"].update(hand_force_set=600, hand_speed_set=800)
    path = tmp_path / "g1_inspire.yaml"
    path.write_text(yaml.safe_dump(raw))
    with Session(dry_options(dev_policy, tmp_path, embodiment=str(path))) as session:
        for side in session.runtime.hands.sides:
            assert side.bus.force_limits.tolist() == [600] * 6 and side.bus.speeds.tolist() == [800] * 6
    with Session(dry_options(dev_policy, tmp_path, hand_force_limit=300)) as session:  # lower is allowed
        assert session.runtime.hands.sides[0].bus.force_limits.tolist() == [300] * 6
        assert session.runtime.hands.sides[0].bus.speeds.tolist() == [1000] * 6


@pytest.mark.parametrize("flag,value,expected", [
    ("--hand-force-limit", "3000", "--hand-force-limit 3000 is above the embodiment's deploy.hand_force_set 1000"),
    ("--hand-speed", "1001", "--hand-speed 1001 is above the embodiment's deploy.hand_speed_set 1000"),
])
def test_hand_settings_above_what_training_assumed_are_refused(dev_policy, tmp_path, capsys, flag, value, expected):
    from deploy.cli import main

    code = main(["--dry-run", "--policy", str(dev_policy), "--log-dir", str(tmp_path), flag, value])
    err = capsys.readouterr().err
    assert code == 2 and expected in err and err.count("\n") == 1, err


# ------------------------------------------------------------------ 8. hand timing that fits the loop
def test_hand_timing_retries_lost_replies_before_the_data_goes_stale():
    from deploy.hand_budget import plan_hand_timing

    plan = plan_hand_timing("serial", 115200, hands_per_link=1, loop_hz=30.0, every_n_ticks=1, max_age_periods=2.0)
    assert plan.stale_s == pytest.approx(2 / 30)
    assert plan.timeout_s < 0.015 and plan.lost_replies >= 2 and plan.retries >= 2
    assert plan.cycle_s + plan.lost_replies * plan.retry_s <= plan.stale_s
    assert f"{plan.lost_replies} lost replies" in plan.message and "66.7 ms" in plan.message
    old = plan_hand_timing("serial", 115200, 1, 30.0, 1, 2.0, timeout_s=0.03)  # the fixed 30 ms per try
    assert old.lost_replies == 1
    can = plan_hand_timing("can", 1_000_000, hands_per_link=2, loop_hz=50.0, every_n_ticks=1, max_age_periods=2.0)
    assert can.lost_replies >= 2


def test_a_lost_reply_that_cannot_be_retried_in_time_is_refused_at_start():
    from deploy.errors import DeployError
    from deploy.hand_budget import plan_hand_timing

    with pytest.raises(DeployError, match=r"--hand-timeout 0\.06.*cannot be retried before .* stale \(66\.7 ms"):
        plan_hand_timing("serial", 115200, 1, 30.0, 1, 2.0, timeout_s=0.06)


def test_two_lost_replies_on_the_wire_are_retried_inside_the_stale_limit():
    """Real bytes: a paced simulated hand on a pty drops two replies; the exchange (write ANGLE_SET, read the
    state) still completes, and in less than the 2-period stale limit of a 30 Hz loop."""
    import time

    from deploy.hand_budget import plan_hand_timing
    from deploy.hands import make_hand_bus
    from deploy.hands.simulated import start_simulated_hand

    plan = plan_hand_timing("serial", 115200, 1, 30.0, 1, 2.0)
    sim = start_simulated_hand("serial", "left")
    bus = make_hand_bus("serial", "left", **sim.bus_kwargs(), timeout=plan.timeout_s, retries=plan.retries)
    try:
        bus.connect()
        took = []
        for _ in range(3):  # the best of three: a loaded machine only ever adds time
            sim.drop_next(2)
            start = time.monotonic()
            bus.write_angles([500] * 6)
            bus.read_state()
            took.append(time.monotonic() - start)
        assert bus.stats.failures["timeout"] == 6
        assert min(took) < plan.stale_s, f"{min(took) * 1e3:.1f} ms >= {plan.stale_s * 1e3:.1f} ms"
    finally:
        bus.disconnect()
        sim.stop()


def test_the_hand_budget_is_printed_at_start_and_used(dev_policy, tmp_path, capsys):
    from deploy.session import Session

    with Session(dry_options(dev_policy, tmp_path, hand_bus="serial")) as session:
        bus = session.runtime.hands.sides[0].bus
        assert bus.timeout < 0.015 and bus.retries >= 2
    err = capsys.readouterr().err
    assert "hand bus:" in err and "lost replies fit" in err, err
    assert "lost replies fit" in session.description["hand_timing"]


def test_a_dead_watchdog_process_is_a_fault(tmp_path):
    import signal

    pytest.importorskip("cyclonedds")
    from deploy.watchdog import ProcessWatchdog

    watchdog = ProcessWatchdog(timeout_s=1.0, damp_s=0.1, period_s=0.02, damp_kd=8.0, num_joints=29,
                               domain_id=100 + os.getpid() % 50, interface="lo", mode_machine=5)
    try:
        watchdog.beat(commanding=True)
        assert watchdog.check() is None
        os.kill(watchdog._proc.pid, signal.SIGKILL)
        watchdog._proc.wait()
        assert watchdog.check().startswith("watchdog process exited (code -9)")
    finally:
        watchdog.close()

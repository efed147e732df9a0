"""UnitreeDdsBody over real DDS on the loopback interface, against a simulated robot on the same topics."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from deploy.body.unitree_dds import UnitreeDdsBody, cyclonedds_available

pytestmark = pytest.mark.skipif(not cyclonedds_available(),
                                reason="cyclonedds not installed (pip install 'cyclonedds==11.0.1')")


def wait_for(predicate, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@pytest.fixture
def loopback():
    from deploy.body.dds_loopback import DdsLoopbackRobot

    domain = 100 + os.getpid() % 100  # keep parallel test runs apart
    robot = DdsLoopbackRobot(domain, "lo", initial_q=np.linspace(-0.2, 0.2, 29)).start()
    body = UnitreeDdsBody(domain_id=domain, interface="lo")
    body.connect()
    yield robot, body
    body.close()
    robot.stop()


def test_state_and_command_round_trip(loopback):
    robot, body = loopback
    assert wait_for(lambda: body.read_state() is not None), "no LowState received"
    state = body.read_state()
    np.testing.assert_allclose(state.q, np.linspace(-0.2, 0.2, 29), atol=1e-6)
    assert state.mode_machine == robot.mode_machine
    np.testing.assert_allclose(state.imu_quat_wxyz, [1, 0, 0, 0])
    target = np.linspace(0.3, -0.3, 29)
    end = time.monotonic() + 10.0
    while robot.commands_received < 20 and time.monotonic() < end:  # the robot keeps only the newest command:
        body.send(target, np.zeros(29), np.full(29, 60.0), np.full(29, 1.5), np.zeros(29))  # on a busy machine
        time.sleep(0.01)  # several sends can arrive as one
    assert robot.commands_received >= 20
    assert robot.crc_errors == 0
    cmd = robot.last_command
    assert cmd.mode_machine == robot.mode_machine and cmd.crc_ok()
    np.testing.assert_allclose(cmd.q[:29], target, atol=1e-6)
    assert np.all(cmd.motor_mode[:29] == 1) and np.all(cmd.motor_mode[29:] == 0)
    assert wait_for(lambda: np.allclose(body.read_state().q, target, atol=1e-3))


def test_state_with_bad_crc_is_dropped_and_goes_stale(loopback):
    robot, body = loopback
    assert wait_for(lambda: body.read_state() is not None)
    robot.corrupt_state_crc = True
    time.sleep(0.05)
    body.read_state()
    errors, stamp = body.crc_errors, body.read_state().stamp
    assert wait_for(lambda: body.read_state() is not None and body.crc_errors >= errors + 3)
    assert body.read_state().stamp == stamp  # nothing with a bad CRC was accepted: the state only ages
    robot.corrupt_state_crc = False
    assert wait_for(lambda: body.read_state().stamp > stamp)


def test_body_reports_identity_health_remote_and_other_commanders(loopback):
    from deploy.body_health import TickWatch, identity_faults
    from deploy.remote import keys_of

    robot, body = loopback
    names = [f"j{i}" for i in range(29)]
    assert wait_for(lambda: body.read_state() is not None)
    state = body.read_state()
    assert state.mode_machine == 5 and state.tick is not None and state.other_commanders == 0
    assert identity_faults(state, names, 5, 90.0) == []
    ticks = {body.read_state().tick for _ in range(3) if time.sleep(0.03) is None}
    assert len(ticks) > 1  # the tick advances

    robot.mode_machine = 6
    robot.motorstate[3] = 0x4
    robot.temperature[10] = 95
    robot.remote_keys = keys_of("B")
    robot.start_other_commander()
    assert wait_for(lambda: body.read_state().other_commanders == 1 and body.read_state().mode_machine == 6)
    state = body.read_state()
    faults = identity_faults(state, names, 5, 90.0)
    assert "mode_machine 6 (G1 29-DoF waist locked rev 1.0)" in faults[0] and "for 5 (G1 29-DoF" in faults[0]
    assert any("other rt/lowcmd publisher" in f for f in faults)
    assert "motor error: j3 motorstate 0x00000004" in faults
    assert any(f.startswith("motor over temperature: j10 at 95 C") for f in faults)
    assert state.remote_keys == keys_of("B") and state.remote_stamp is not None
    robot.stop_other_commander()
    assert wait_for(lambda: body.read_state().other_commanders == 0)

    robot.remote_connected = False  # the remote stops reporting: its stamp stops advancing, its keys read as none
    assert wait_for(lambda: body.read_state().remote_keys == 0)
    silent_since = body.read_state().remote_stamp
    time.sleep(0.05)
    assert body.read_state().remote_stamp == silent_since < body.read_state().stamp

    robot.tick_frozen = True
    time.sleep(0.05)
    watch = TickWatch(max_age_s=0.1)
    start = time.monotonic()
    assert watch.fault(body.read_state(), start) is None
    time.sleep(0.05)
    assert body.read_state().stamp > start  # states keep arriving: fresh by arrival time alone
    assert "body tick frozen" in watch.fault(body.read_state(), start + 0.2)

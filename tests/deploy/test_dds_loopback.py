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
    for _ in range(20):
        body.send(target, np.zeros(29), np.full(29, 60.0), np.full(29, 1.5), np.zeros(29))
        time.sleep(0.01)
    assert wait_for(lambda: robot.commands_received >= 20)
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

"""deploy's Body and PoseTracker over the simulated world: exact readings, noise, latency, stamps."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from deploy.errors import BodyLinkError
from sim2sim.perturbations import NOMINAL
from sim2sim.sensors import MujocoBody, MujocoTracker


def test_body_reads_the_world_and_sends_lowcmds(make_world, contract):
    world = make_world()
    body = MujocoBody(world, contract.num_body, NOMINAL, np.random.default_rng(0))
    with pytest.raises(BodyLinkError):
        body.read_state()
    body.connect()
    world.advance_to(0.1)
    state = body.read_state()
    assert state.stamp == pytest.approx(0.1)
    np.testing.assert_array_equal(state.q, world.data.qpos[world.layout.body_qpos])
    np.testing.assert_array_equal(state.imu_quat_wxyz, world.data.qpos[3:7])
    n = contract.num_body
    body.send(contract.default_pose[:n], np.zeros(n), contract.kp[:n], contract.kd[:n], np.zeros(n))
    assert world.commands_received == 1
    with pytest.raises(ValueError):
        body.send(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))


def test_body_noise(make_world, contract):
    world = make_world()
    noisy = MujocoBody(world, contract.num_body, replace(NOMINAL, joint_pos_noise=0.01, gyro_noise=0.05),
                       np.random.default_rng(0))
    noisy.connect()
    true_q = world.data.qpos[world.layout.body_qpos].copy()
    errors = np.array([noisy.read_state().q - true_q for _ in range(400)])
    assert errors.std() == pytest.approx(0.01, rel=0.1)
    assert abs(errors.mean()) < 0.002


def test_tracker_latency_and_stamps(make_world):
    world = make_world()
    tracker = MujocoTracker(world, replace(NOMINAL, tracker_latency_s=0.05), np.random.default_rng(0), rate_hz=100)
    poses = tracker.read()
    assert not np.isfinite(poses.robot.stamp)  # nothing delivered yet
    world.advance_to(0.2)
    poses = tracker.read()
    assert 0.14 <= poses.robot.stamp <= 0.15 + 1e-9  # captured >= 50 ms ago, at the 100 Hz sample grid
    assert poses.object.stamp == poses.robot.stamp
    np.testing.assert_allclose(poses.object.pos, world.object_pose()[0], atol=1e-3)  # the object rests


def test_tracker_noise(make_world):
    world = make_world()
    tracker = MujocoTracker(world, replace(NOMINAL, tracker_pos_noise=0.005), np.random.default_rng(0))
    world.advance_to(0.05)
    truth = world.pelvis_pose()[0]
    errors = np.array([tracker.read().robot.pos - truth for _ in range(400)])
    assert errors.std() == pytest.approx(0.005, rel=0.15)

"""Pose trackers: UDP packet format and receiver, simulated tracker (latency, noise, drop-out), replay."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest

from deploy.clock import FakeClock
from deploy.errors import DeployError
from deploy.motion import ReferenceMotion
from deploy.tracking import Pose, ReplayTracker, SimulatedTracker
from deploy.tracking_udp import PACKET, UdpPoseReceiver, UdpPoseSender, decode_pose_packet, encode_pose_packet

IDENTITY = np.array([1.0, 0, 0, 0])


def make_motion(num=10) -> ReferenceMotion:
    t = np.arange(num, dtype=float)
    return ReferenceMotion(
        fps=10.0,
        joint_pos=np.zeros((num, 41)),
        root_pos=np.stack([t, np.zeros(num), np.full(num, 0.8)], axis=1),
        root_quat_wxyz=np.tile(IDENTITY, (num, 1)),
        link_pos=np.zeros((num, 2, 3)),
        object_pos=np.stack([t, np.ones(num), np.full(num, 0.5)], axis=1),
        object_quat_wxyz=np.tile(IDENTITY, (num, 1)),
    )


def test_packet_layout_is_76_little_endian_bytes():
    robot = Pose(np.array([1.0, 2.0, 3.0]), np.array([0.0, 1.0, 0.0, 0.0]))
    data = encode_pose_packet(7, 12.5, robot, None)
    assert PACKET.size == len(data) == 76
    assert data[:4] == b"RHTK"
    assert struct.unpack_from("<HHId", data, 4) == (1, 1, 7, 12.5)
    assert struct.unpack_from("<3f", data, 20) == (1.0, 2.0, 3.0)
    assert struct.unpack_from("<4f", data, 32) == (0.0, 1.0, 0.0, 0.0)
    seq, stamp, r, o = decode_pose_packet(data)
    assert seq == 7 and stamp == 12.5 and o is None
    np.testing.assert_allclose(r[0], [1, 2, 3])


@pytest.mark.parametrize("mutate,reason", [
    (lambda d: d[:-1], "size"),
    (lambda d: b"XXXX" + d[4:], "magic"),
    (lambda d: d[:4] + struct.pack("<H", 9) + d[6:], "version"),
    (lambda d: d[:20] + struct.pack("<f", float("nan")) + d[24:], "non-finite"),
    (lambda d: d[:32] + struct.pack("<4f", 2, 0, 0, 0) + d[48:], "quaternion norm"),
])
def test_bad_packets_are_refused(mutate, reason):
    data = encode_pose_packet(1, 0.0, Pose(np.zeros(3), IDENTITY), Pose(np.zeros(3), IDENTITY))
    with pytest.raises(ValueError, match=reason):
        decode_pose_packet(mutate(data))


def test_receiver_stamps_orders_and_counts():
    clock = FakeClock()
    rx = UdpPoseReceiver(port=0, clock=clock)
    pose = Pose(np.array([0.1, 0.2, 0.8]), IDENTITY)
    rx.handle_packet(encode_pose_packet(10, 0.0, pose, None))
    assert rx.read().robot.stamp == clock.now()
    assert rx.read().object.stamp == float("-inf")  # object never seen
    clock.advance(0.1)
    rx.handle_packet(encode_pose_packet(9, 0.0, Pose(np.ones(3), IDENTITY), None))  # older: dropped
    rx.handle_packet(b"garbage")
    assert rx.stale_packets == 1 and rx.bad_packets == 1
    np.testing.assert_allclose(rx.read().robot.pos, [0.1, 0.2, 0.8], rtol=1e-6)
    assert rx.read().robot.age(clock.now()) == pytest.approx(0.1)
    rx.handle_packet(encode_pose_packet(0xFFFFFFFF, 0.0, pose, pose))  # "older" than 10 modulo 2^32: dropped
    assert rx.stale_packets == 2

    wrap = UdpPoseReceiver(port=0, clock=clock)
    wrap.handle_packet(encode_pose_packet(0xFFFFFFFF, 0.0, pose, pose))
    wrap.handle_packet(encode_pose_packet(0, 0.0, Pose(np.array([5.0, 0, 0]), IDENTITY), None))  # wraps around
    assert wrap.read().robot.pos[0] == 5.0 and wrap.packets == 2 and wrap.stale_packets == 0


def test_receiver_over_a_real_socket():
    rx = UdpPoseReceiver(port=0)
    rx.connect()
    try:
        tx = UdpPoseSender(port=rx.port)
        for i in range(3):
            tx.send(Pose(np.array([i, 0, 0.8]), IDENTITY), Pose(np.array([1.0, i, 0.5]), IDENTITY))
        deadline = time.monotonic() + 2.0
        while rx.packets < 3 and time.monotonic() < deadline:
            time.sleep(0.005)
        poses = rx.read()
        assert rx.packets == 3
        np.testing.assert_allclose(poses.object.pos, [1, 2, 0.5])
        assert poses.robot.age(time.monotonic()) < 1.0
        tx.close()
    finally:
        rx.close()


def test_receiver_port_in_use_is_a_user_error():
    first = UdpPoseReceiver(port=0)
    first.connect()
    try:
        with pytest.raises(DeployError, match="cannot bind"):
            UdpPoseReceiver(port=first.port).connect()
    finally:
        first.close()


def test_simulated_tracker_follows_reference_with_latency():
    clock = FakeClock()
    tracker = SimulatedTracker(make_motion(), clock=clock, latency_s=0.05)
    assert tracker.read().robot.pos[0] == 0.0
    tracker.update_reference(3)
    clock.advance(0.02)
    seen = tracker.read()
    assert seen.robot.pos[0] == 0.0 and seen.robot.stamp == pytest.approx(clock.now() - 0.05)  # not yet visible
    clock.advance(0.04)
    assert tracker.read().robot.pos[0] == 3.0 and tracker.read().object.pos[1] == 1.0
    tracker.update_reference(99)  # clamps at the last frame
    clock.advance(0.1)
    assert tracker.read().robot.pos[0] == 9.0


def test_simulated_tracker_drop_freezes_the_stamp():
    clock = FakeClock()
    tracker = SimulatedTracker(make_motion(), clock=clock)
    tracker.drop("object")
    frozen = tracker.read().object.stamp
    clock.advance(1.0)
    assert tracker.read().object.stamp == frozen and tracker.read().robot.stamp == clock.now()
    tracker.restore("object")
    assert tracker.read().object.stamp == clock.now()


def test_simulated_tracker_noise_is_seeded_and_small():
    clock = FakeClock()
    a = SimulatedTracker(make_motion(), clock=clock, pos_noise_std=0.01, rot_noise_std=0.01, seed=3)
    b = SimulatedTracker(make_motion(), clock=clock, pos_noise_std=0.01, rot_noise_std=0.01, seed=3)
    pa, pb = a.read().robot, b.read().robot
    np.testing.assert_array_equal(pa.pos, pb.pos)
    assert 0 < np.linalg.norm(pa.pos - [0, 0, 0.8]) < 0.1
    assert np.linalg.norm(pa.quat_wxyz) == pytest.approx(1.0)


def test_replay_tracker_plays_in_real_time():
    clock = FakeClock()
    tracker = ReplayTracker(make_motion(), clock=clock)
    tracker.connect()
    clock.advance(0.35)  # 10 fps -> frame 3
    assert tracker.read().robot.pos[0] == 3.0
    clock.advance(10.0)
    assert tracker.read().robot.pos[0] == 9.0  # holds the last frame

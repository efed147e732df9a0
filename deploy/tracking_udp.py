"""Motion-capture poses over UDP: a documented little-endian packet, a receiver thread, and a sender.

Packet (76 bytes, little-endian, struct '<4sHHId3f4f3f4f'):

    offset size  field
    0      4     magic b"RHTK"
    4      2     version uint16 = 1
    6      2     flags uint16: bit 0 = robot pose valid, bit 1 = object pose valid
    8      4     seq uint32, +1 per packet (wraps); older or repeated packets are dropped
    12     8     stamp float64, sender's clock in s (kept for latency statistics; clocks are not synced)
    20     12    robot (pelvis) position float32 x, y, z in m, world frame, z up
    32     16    robot orientation float32 quaternion w, x, y, z
    48     12    object position float32 x, y, z
    60     16    object orientation float32 quaternion w, x, y, z

The receiver binds 127.0.0.1:9870 by default (pass host "0.0.0.0" to accept from the network). Each valid pose is
stamped with the runtime clock when its packet arrives; the runtime's staleness check does the rest. Packets with
a wrong size, magic or version, non-finite values or a non-unit quaternion are counted and dropped.
"""

from __future__ import annotations

import math
import socket
import struct
import threading

import numpy as np

from deploy.clock import Clock, MonotonicClock
from deploy.errors import DeployError
from deploy.tracking import Pose, PoseTracker, TrackedPoses, unseen_pose

PACKET = struct.Struct("<4sHHId3f4f3f4f")
MAGIC = b"RHTK"
VERSION = 1
FLAG_ROBOT = 1
FLAG_OBJECT = 2
DEFAULT_PORT = 9870


def encode_pose_packet(seq: int, stamp: float, robot: Pose | None, obj: Pose | None) -> bytes:
    flags = (FLAG_ROBOT if robot is not None else 0) | (FLAG_OBJECT if obj is not None else 0)
    zero = (np.zeros(3), np.array([1.0, 0, 0, 0]))
    rp, rq = (robot.pos, robot.quat_wxyz) if robot is not None else zero
    op, oq = (obj.pos, obj.quat_wxyz) if obj is not None else zero
    return PACKET.pack(MAGIC, VERSION, flags, seq & 0xFFFFFFFF, float(stamp), *map(float, rp), *map(float, rq),
                       *map(float, op), *map(float, oq))


def decode_pose_packet(data: bytes) -> tuple[int, float, tuple | None, tuple | None]:
    """(seq, sender stamp, (pos, quat) or None, (pos, quat) or None); ValueError says why a packet is bad."""
    if len(data) != PACKET.size:
        raise ValueError(f"size {len(data)} != {PACKET.size}")
    magic, version, flags, seq, stamp, *values = PACKET.unpack(data)
    if magic != MAGIC:
        raise ValueError(f"magic {magic!r}")
    if version != VERSION:
        raise ValueError(f"version {version}")
    v = np.array(values, dtype=np.float64)
    if not np.all(np.isfinite(v)) or not math.isfinite(stamp):
        raise ValueError("non-finite value")
    poses = []
    for flag, chunk in ((FLAG_ROBOT, v[:7]), (FLAG_OBJECT, v[7:])):
        if not flags & flag:
            poses.append(None)
            continue
        quat = chunk[3:]
        norm = float(np.linalg.norm(quat))
        if abs(norm - 1.0) > 0.05:
            raise ValueError(f"quaternion norm {norm:.3f}")
        poses.append((chunk[:3].copy(), quat / norm))
    return seq, stamp, poses[0], poses[1]


class UdpPoseReceiver(PoseTracker):
    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, clock: Clock | None = None):
        self.host = host
        self.port = port
        self.clock = clock or MonotonicClock()
        self._lock = threading.Lock()
        self._robot = unseen_pose()
        self._object = unseen_pose()
        self._last_seq: int | None = None
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.packets = 0
        self.bad_packets = 0
        self.stale_packets = 0
        self.last_bad_reason = ""

    def connect(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise DeployError(f"pose tracker: cannot bind UDP {self.host}:{self.port} ({exc})") from None
        sock.settimeout(0.05)
        self.port = sock.getsockname()[1]  # resolves port 0 to the one the OS picked
        self._sock = sock
        self._stop.clear()
        self._thread = threading.Thread(target=self._receive_loop, name="udp-pose-receiver", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _receive_loop(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._sock.recv(2048)
            except TimeoutError:
                continue
            except OSError:
                return
            self.handle_packet(data)

    def handle_packet(self, data: bytes) -> None:
        now = self.clock.now()
        with self._lock:
            try:
                seq, _stamp, robot, obj = decode_pose_packet(data)
            except ValueError as exc:
                self.bad_packets += 1
                self.last_bad_reason = str(exc)
                return
            if self._last_seq is not None and not 0 < ((seq - self._last_seq) & 0xFFFFFFFF) < 0x80000000:
                self.stale_packets += 1
                return
            self._last_seq = seq
            self.packets += 1
            if robot is not None:
                self._robot = Pose(robot[0], robot[1], now)
            if obj is not None:
                self._object = Pose(obj[0], obj[1], now)

    def read(self) -> TrackedPoses:
        with self._lock:
            return TrackedPoses(robot=self._robot, object=self._object)


class UdpPoseSender:
    """Sends pose packets (a motion-capture bridge would do this); used by tests and the dry run."""

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT):
        self.address = (host, port)
        self.seq = 0
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(self, robot: Pose | None, obj: Pose | None, stamp: float = 0.0) -> None:
        self._sock.sendto(encode_pose_packet(self.seq, stamp, robot, obj), self.address)
        self.seq = (self.seq + 1) & 0xFFFFFFFF

    def close(self) -> None:
        self._sock.close()

"""The real G1 body over DDS: publish rt/lowcmd, subscribe rt/lowstate (Unitree "hg" message family).

Message types are declared here as cyclonedds IdlStruct dataclasses with the robot's type names and field layout
(unitree_hg.msg.dds_.*), so no Unitree SDK is needed. cyclonedds is an optional dependency
(`pip install robot-hoi[deploy-dds]`, i.e. cyclonedds==11.0.1); without it the module still imports and
`UnitreeDdsBody.connect()` raises a clear MissingDependencyError.

States are stamped with the runtime clock when they are taken, so a silent robot shows up as a stale state;
LowState messages with a wrong CRC are counted and dropped. Each state also reports mode_machine, tick, motor
error bits and temperatures, the wireless remote's buttons and how many other rt/lowcmd writers are matched (a
reader that ignores our own participant), for deploy.body_health and the operator. Commands echo the robot's
mode_machine and carry the CRC from deploy.body.unitree_lowlevel.
"""

from __future__ import annotations

import logging
import threading

import numpy as np

from deploy.body.base import Body, BodyState
from deploy.body.unitree_lowlevel import NUM_MOTOR_SLOTS, LowCmdFrame, LowStateFrame, make_lowcmd
from deploy.clock import Clock, MonotonicClock
from deploy.errors import BodyLinkError, MissingDependencyError
from deploy.remote import keys_from_wireless_remote, remote_reporting

log = logging.getLogger(__name__)

LOWCMD_TOPIC = "rt/lowcmd"
LOWSTATE_TOPIC = "rt/lowstate"


def cyclonedds_available() -> bool:
    try:
        import cyclonedds.idl  # noqa: F401
    except ImportError:
        return False
    return True


def _require_cyclonedds() -> None:
    if not cyclonedds_available():
        raise MissingDependencyError(
            "the DDS body needs cyclonedds: pip install 'cyclonedds==11.0.1' (or robot-hoi[deploy-dds])"
        )


def idl_types():
    """The Unitree hg IdlStruct types module (imported on first use so this module imports without cyclonedds)."""
    _require_cyclonedds()
    from deploy.body import unitree_idl

    return unitree_idl


def lowcmd_to_idl(frame: LowCmdFrame):
    T = idl_types()
    motors = [
        T.MotorCmd_(int(frame.motor_mode[i]), float(frame.q[i]), float(frame.dq[i]), float(frame.tau[i]),
                    float(frame.kp[i]), float(frame.kd[i]), int(frame.motor_reserve[i]))
        for i in range(NUM_MOTOR_SLOTS)
    ]
    return T.LowCmd_(frame.mode_pr, frame.mode_machine, motors, [int(v) for v in frame.reserve], frame.crc)


def idl_to_lowcmd(msg) -> LowCmdFrame:
    m = msg.motor_cmd
    return LowCmdFrame(
        mode_pr=msg.mode_pr,
        mode_machine=msg.mode_machine,
        motor_mode=np.array([c.mode for c in m], dtype=np.uint8),
        q=np.array([c.q for c in m], dtype=np.float32),
        dq=np.array([c.dq for c in m], dtype=np.float32),
        tau=np.array([c.tau for c in m], dtype=np.float32),
        kp=np.array([c.kp for c in m], dtype=np.float32),
        kd=np.array([c.kd for c in m], dtype=np.float32),
        motor_reserve=np.array([c.reserve for c in m], dtype=np.uint32),
        reserve=np.array(msg.reserve, dtype=np.uint32),
        crc=msg.crc,
    )


def lowstate_to_idl(frame: LowStateFrame):
    T = idl_types()
    imu = T.IMUState_([float(v) for v in frame.imu_quat_wxyz], [float(v) for v in frame.imu_gyro],
                      [float(v) for v in frame.imu_acc], [float(v) for v in frame.imu_rpy], int(frame.imu_temperature))
    motors = [
        T.MotorState_(int(frame.motor_mode[i]), float(frame.q[i]), float(frame.dq[i]), float(frame.ddq[i]),
                      float(frame.tau_est[i]), [int(v) for v in frame.temperature[i]], float(frame.vol[i]),
                      [int(v) for v in frame.sensor[i]], int(frame.motorstate[i]),
                      [int(v) for v in frame.motor_reserve[i]])
        for i in range(NUM_MOTOR_SLOTS)
    ]
    return T.LowState_([int(v) for v in frame.version], frame.mode_pr, frame.mode_machine, frame.tick, imu, motors,
                       bytes(frame.wireless_remote.astype(np.uint8)), [int(v) for v in frame.reserve], frame.crc)


def idl_to_lowstate(msg) -> LowStateFrame:
    m = msg.motor_state
    imu = msg.imu_state
    return LowStateFrame(
        version=np.array(msg.version, dtype=np.uint32),
        mode_pr=msg.mode_pr,
        mode_machine=msg.mode_machine,
        tick=msg.tick,
        imu_quat_wxyz=np.array(imu.quaternion, dtype=np.float32),
        imu_gyro=np.array(imu.gyroscope, dtype=np.float32),
        imu_acc=np.array(imu.accelerometer, dtype=np.float32),
        imu_rpy=np.array(imu.rpy, dtype=np.float32),
        imu_temperature=imu.temperature,
        motor_mode=np.array([s.mode for s in m], dtype=np.uint8),
        q=np.array([s.q for s in m], dtype=np.float32),
        dq=np.array([s.dq for s in m], dtype=np.float32),
        ddq=np.array([s.ddq for s in m], dtype=np.float32),
        tau_est=np.array([s.tau_est for s in m], dtype=np.float32),
        temperature=np.array([s.temperature for s in m], dtype=np.int16),
        vol=np.array([s.vol for s in m], dtype=np.float32),
        sensor=np.array([s.sensor for s in m], dtype=np.uint32),
        motorstate=np.array([s.motorstate for s in m], dtype=np.uint32),
        motor_reserve=np.array([s.reserve for s in m], dtype=np.uint32),
        wireless_remote=np.frombuffer(bytes(msg.wireless_remote), dtype=np.uint8).copy(),
        reserve=np.array(msg.reserve, dtype=np.uint32),
        crc=msg.crc,
    )


def dds_domain_config(interface: str | None) -> str | None:
    """Cyclone DDS XML that pins the network interface (e.g. the robot's eth0, or lo for tests)."""
    if not interface:
        return None
    return (
        '<CycloneDDS><Domain id="any"><General><Interfaces>'
        f'<NetworkInterface name="{interface}"/></Interfaces></General></Domain></CycloneDDS>'
    )


_DOMAINS: dict[int, object] = {}


def dds_participant(domain_id: int, interface: str | None):
    """A DomainParticipant on `domain_id`, pinned to `interface` (cyclonedds allows one configured Domain per id
    and process: the first caller's interface holds)."""
    from cyclonedds.domain import Domain, DomainParticipant

    config = dds_domain_config(interface)
    if config and domain_id not in _DOMAINS:
        _DOMAINS[domain_id] = Domain(domain_id, config)
    return DomainParticipant(domain_id)


class DdsEndpoint:
    """One DDS participant with a reader (history: the newest sample only) and a writer.

    With `on_sample`, samples are taken by our own thread blocked on a WaitSet (the loopback robot receiving
    commands). Without it, the owner calls `take_latest()` (the body, once per control tick: the 500 Hz LowState
    stream is then deserialised at the loop's rate, not 500 times a second). No DDS listeners: a listener runs in
    cyclonedds' threads and deleting entities while one runs can deadlock. close() stops our thread first.
    """

    def __init__(self, domain_id: int, interface: str | None, read_topic: str, read_type, write_topic: str,
                 write_type, on_sample=None):
        _require_cyclonedds()
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.pub import DataWriter
        from cyclonedds.qos import Policy, Qos
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        self.participant = dds_participant(domain_id, interface)
        self.reader = DataReader(self.participant, Topic(self.participant, read_topic, read_type),
                                 qos=Qos(Policy.History.KeepLast(1)))
        self.writer = DataWriter(self.participant, Topic(self.participant, write_topic, write_type))
        self._on_sample = on_sample
        self._topic_name = read_topic
        self.callback_errors = 0
        self._stop = threading.Event()
        self._thread = None
        if on_sample is not None:
            self._waitset = WaitSet(self.participant)
            self._waitset.attach(ReadCondition(self.reader, SampleState.Any | ViewState.Any | InstanceState.Any))
            self._thread = threading.Thread(target=self._receive, name=f"dds-{read_topic}", daemon=True)
            self._thread.start()

    def take_latest(self):
        """The newest sample not taken yet, or None."""
        samples = self.reader.take(N=1)
        return samples[-1] if samples else None

    def _receive(self) -> None:
        from cyclonedds.util import duration

        timeout = duration(milliseconds=50)
        while not self._stop.is_set():
            self._waitset.wait(timeout)
            for sample in self.reader.take(N=64):
                try:
                    self._on_sample(sample)
                except Exception:  # a malformed sample must not kill the receiver; counted, then dropped
                    self.callback_errors += 1
                    log.debug("dropped a malformed %s sample", self._topic_name, exc_info=True)

    def write(self, msg) -> None:
        self.writer.write(msg)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        # Dropping the references lets cyclonedds delete the entities (the participant owns the rest).
        self._waitset = self.reader = self.writer = self.participant = None


class UnitreeDdsBody(Body):
    def __init__(self, num_joints: int = 29, domain_id: int = 0, interface: str | None = None,
                 clock: Clock | None = None, mode_pr: int = 0, check_state_crc: bool = True):
        self.num_joints = num_joints
        self.domain_id = domain_id
        self.interface = interface
        self.clock = clock or MonotonicClock()
        self.mode_pr = mode_pr
        self.check_state_crc = check_state_crc
        self._latest: BodyState | None = None
        self._remote_stamp: float | None = None  # when the wireless remote last reported (deploy.remote)
        self._endpoint: DdsEndpoint | None = None
        self._lowcmd_watch = None  # reader of rt/lowcmd that ignores our own writer: counts other commanders
        self.states_received = 0
        self.crc_errors = 0
        self.commands_sent = 0

    def connect(self) -> None:
        T = idl_types()
        try:
            self._endpoint = DdsEndpoint(self.domain_id, self.interface, LOWSTATE_TOPIC, T.LowState_,
                                         LOWCMD_TOPIC, T.LowCmd_)
        except MissingDependencyError:
            raise
        except Exception as exc:  # cyclonedds raises DDSException on a bad interface / domain
            raise BodyLinkError(f"DDS setup failed on interface {self.interface!r}: {exc}") from exc
        from cyclonedds.qos import Policy, Qos
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        participant = self._endpoint.participant
        self._lowcmd_watch = DataReader(participant, Topic(participant, LOWCMD_TOPIC, T.LowCmd_),
                                        qos=Qos(Policy.History.KeepLast(1), Policy.IgnoreLocal.Participant))

    def close(self) -> None:
        self._lowcmd_watch = None
        if self._endpoint is not None:
            self._endpoint.close()
            self._endpoint = None

    def _accept(self, msg, stamp: float) -> None:
        frame = idl_to_lowstate(msg)
        if self.check_state_crc and not frame.crc_ok():
            self.crc_errors += 1
            return
        n = self.num_joints
        if remote_reporting(frame.wireless_remote):
            self._remote_stamp = stamp
        self._latest = BodyState(
            q=frame.q[:n].astype(np.float64),
            dq=frame.dq[:n].astype(np.float64),
            imu_quat_wxyz=frame.imu_quat_wxyz.astype(np.float64),
            gyro=frame.imu_gyro.astype(np.float64),
            stamp=stamp,
            tau_est=frame.tau_est[:n].astype(np.float64),
            mode_machine=int(frame.mode_machine),
            tick=int(frame.tick),
            motor_error=frame.motorstate[:n].copy(),
            motor_temp_c=frame.temperature[:n].max(axis=1).astype(np.float64),
            remote_keys=keys_from_wireless_remote(frame.wireless_remote),
            remote_stamp=self._remote_stamp,
        )
        self.states_received += 1

    def read_state(self) -> BodyState | None:
        """Take the newest LowState (if one arrived since the last call) and stamp it now.

        The robot publishes at 500 Hz, so a new sample is at most ~2 ms old; when the robot falls silent no new
        sample comes and the returned state keeps its old stamp (the runtime sees it go stale).
        """
        if self._endpoint is None:
            raise BodyLinkError("DDS body is not connected")
        msg = self._endpoint.take_latest()
        if msg is not None:
            self._accept(msg, self.clock.now())
        if self._latest is not None and self._lowcmd_watch is not None:
            self._latest.other_commanders = self._lowcmd_watch.get_subscription_matched_status().current_count
        return self._latest

    def send(self, q: np.ndarray, dq: np.ndarray, kp: np.ndarray, kd: np.ndarray, tau: np.ndarray) -> None:
        if self._endpoint is None:
            raise BodyLinkError("DDS body is not connected")
        self._check_command(q, dq, kp, kd, tau)
        mode_machine = self._latest.mode_machine if self._latest is not None else 0
        frame = make_lowcmd(q, dq, kp, kd, tau, mode_machine=mode_machine, mode_pr=self.mode_pr)
        self._endpoint.write(lowcmd_to_idl(frame))
        self.commands_sent += 1

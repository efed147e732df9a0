"""A simulated G1 that speaks the real DDS topics: subscribes rt/lowcmd, publishes rt/lowstate.

For developing and testing UnitreeDdsBody on one machine (loopback interface, its own domain id). Behind the
topics it runs deploy.body.simulated.SimulatedBody; commands with a wrong CRC are counted and ignored, as the
robot does. It publishes at 100 Hz by default (the robot: 500 Hz) because serialising in Python costs ~0.4 ms a
message and this robot shares the runtime's process in dry runs. Needs cyclonedds.

What it reports can be changed on demand: `mode_machine`, `tick_frozen`, `motorstate` and `temperature` (per
motor slot), `remote_keys` (wireless remote buttons; `remote_connected` False sends a remote's absence: zeros),
and start_other_commander() adds a second rt/lowcmd writer
(what sport mode left running looks like).
"""

from __future__ import annotations

import threading

import numpy as np

from deploy.body.simulated import SimulatedBody
from deploy.body.unitree_dds import (
    LOWCMD_TOPIC,
    LOWSTATE_TOPIC,
    DdsEndpoint,
    idl_to_lowcmd,
    idl_types,
    lowstate_to_idl,
)
from deploy.body.unitree_lowlevel import LowStateFrame
from deploy.clock import MonotonicClock
from deploy.remote import wireless_remote_bytes


class DdsLoopbackRobot:
    def __init__(self, domain_id: int, interface: str | None = "lo", num_joints: int = 29, rate_hz: float = 100.0,
                 mode_machine: int = 5, initial_q: np.ndarray | None = None):
        self.domain_id = domain_id
        self.interface = interface
        self.rate_hz = rate_hz
        self.mode_machine = mode_machine
        self.body = SimulatedBody(num_joints, clock=MonotonicClock(), initial_q=initial_q)
        self.num_joints = num_joints
        self.commands_received = 0
        self.crc_errors = 0
        self.last_command = None
        self.corrupt_state_crc = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._endpoint: DdsEndpoint | None = None
        self._lock = threading.Lock()
        self._tick = 0
        self.tick_frozen = False
        self.motorstate = np.zeros(num_joints, dtype=np.uint32)
        self.temperature = np.full(num_joints, 40, dtype=np.int16)
        self.remote_keys = 0
        self.remote_connected = True
        self._other_commander = None

    def start(self) -> DdsLoopbackRobot:
        T = idl_types()
        self.body.connect()
        self._endpoint = DdsEndpoint(self.domain_id, self.interface, LOWCMD_TOPIC, T.LowCmd_, LOWSTATE_TOPIC,
                                     T.LowState_, self._on_command)
        self._thread = threading.Thread(target=self._publish_loop, name="dds-loopback-robot", daemon=True)
        self._thread.start()
        return self

    def _on_command(self, msg) -> None:
        frame = idl_to_lowcmd(msg)
        with self._lock:
            if not frame.crc_ok():
                self.crc_errors += 1
                return
            self.commands_received += 1
            self.last_command = frame
            n = self.num_joints
            self.body.send(frame.q[:n], frame.dq[:n], frame.kp[:n], frame.kd[:n], frame.tau[:n])

    def _publish_loop(self) -> None:
        period = 1.0 / self.rate_hz
        clock = self.body.clock
        deadline = clock.now()
        while not self._stop.is_set():
            with self._lock:
                state = self.body.read_state()
            frame = LowStateFrame(mode_machine=self.mode_machine, tick=self._tick)
            n = self.num_joints
            frame.q[:n], frame.dq[:n] = state.q, state.dq
            frame.imu_quat_wxyz[:] = state.imu_quat_wxyz
            frame.motorstate[:n] = self.motorstate
            frame.temperature[:n] = self.temperature[:, None]
            frame.wireless_remote[:] = np.frombuffer(wireless_remote_bytes(self.remote_keys, self.remote_connected),
                                                       dtype=np.uint8)
            frame.with_crc()
            if self.corrupt_state_crc:
                frame.crc ^= 0x1
            self._endpoint.write(lowstate_to_idl(frame))
            self._tick += 0 if self.tick_frozen else 1
            deadline += period
            clock.sleep_until(deadline)

    def start_other_commander(self) -> None:
        """A second rt/lowcmd writer in its own participant (it sends nothing; being matched is enough)."""
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        participant = DomainParticipant(self.domain_id)
        self._other_commander = (participant, DataWriter(participant, Topic(participant, LOWCMD_TOPIC,
                                                                            idl_types().LowCmd_)))

    def stop_other_commander(self) -> None:
        self._other_commander = None  # dropping the references deletes the writer

    def stop(self) -> None:
        self._other_commander = None
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._endpoint is not None:
            self._endpoint.close()
            self._endpoint = None

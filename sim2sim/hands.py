"""The Inspire hands in sim2sim: deploy's simulated devices (real bytes) with MuJoCo fingers.

The runtime talks to two `deploy.hands.simulated` devices through its ordinary HandBus classes, so every
ANGLE_SET write and ANGLE_ACT / FORCE_ACT read crosses the chosen transport's real framing. Links:
    "direct" (serial, modbus; default): the device object parses and answers each request in the caller's
             thread, bytes handed over in memory (sim2sim.protocol_simhand): fast and deterministic;
    "pty":   the device's own thread on a pseudo-terminal (serial, modbus) or a python-can virtual channel
             (can), exactly as `robot-hoi deploy --dry-run` runs it (a thread hand-off per request).
Each device's FingerModel is driven by MuJoCo instead of its own first-order model (FingerModel.set_measured):

    every hand period (default 100 Hz):
        measured ANGLE_ACT = 1000 * (q_joint - closed) / (open - closed) of each channel's driving joint,
        measured FORCE_ACT = |net contact force on the finger chain| in grams (training's hand_force sensors),
        the servo set-point slews toward ANGLE_SET at SPEED_SET (1000 = full stroke in 0.6 s, the manual),
        and stops closing while the finger's force is at or above FORCE_SET (the device's force limit),
        MuJoCo's hand position actuator gets the set-point in radians.
"""

from __future__ import annotations

import numpy as np

from deploy.contract import PolicyContract
from deploy.hand_pair import Hands
from deploy.hand_units import HAND_SIDES, UNITS_OPEN, channel_arrays
from deploy.hands import make_hand_bus
from deploy.hands.finger_model import FULL_STROKE_S, FingerModel
from deploy.hands.sim_serial import SimulatedModbusHand, SimulatedSerialHand
from deploy.hands.simulated import start_simulated_hand
from sim2sim.protocol_simhand import register_device, unregister_device
from sim2sim.world import SimWorld

HAND_LINKS = ("direct", "pty")
DIRECT_TRANSPORTS = ("serial", "modbus")
GRAMS_PER_NEWTON = 1.0 / 9.81e-3
DOF = 6


class SimulatedInspireHands:
    """Two simulated Inspire devices whose fingers are the world's hand joints; `hands` is deploy's Hands."""

    def __init__(self, world: SimWorld, contract: PolicyContract, clock, transport: str = "serial",
                 link: str = "direct", rate_hz: float = 100.0, force_limit: int = 1000, speed: int = 1000):
        if link not in HAND_LINKS:
            raise ValueError(f"hand link must be one of {HAND_LINKS}, got {link!r}")
        if link == "direct" and transport not in DIRECT_TRANSPORTS:
            raise ValueError(f"the direct hand link serves {DIRECT_TRANSPORTS}; use link 'pty' for {transport}")
        self.world = world
        self.transport = transport
        self.link = link
        self._names: list[str] = []
        opens, closes = zip(*(channel_arrays(contract.hands[s]) for s in HAND_SIDES), strict=True)
        self.open_rad = np.concatenate(opens)
        self.closed_rad = np.concatenate(closes)
        self.fingers = {side: FingerModel(clock=clock.now) for side in HAND_SIDES}
        self.setpoint = np.full(2 * DOF, float(UNITS_OPEN))
        self.dt = 1.0 / rate_hz
        self.devices = []
        self.hands: Hands | None = None
        hand_ids = [1, 2] if transport == "can" else [1, 1]
        try:
            for side, hand_id in zip(HAND_SIDES, hand_ids, strict=True):
                self.devices.append(self._device(side, hand_id))
            buses = [make_hand_bus(transport, side, **self._bus_kwargs(dev), retries=2, safe_pose="hold")
                     for side, dev in zip(HAND_SIDES, self.devices, strict=True)]
            self.hands = Hands(buses[0], buses[1], contract.hands, clock=clock, force_limits=[force_limit] * DOF,
                               speeds=[speed] * DOF, safe_state="hold", threaded=False)
            self._measure()
            world.set_hand_targets(self._rad(self.setpoint))
            world.add_listener(self.dt, self.update)
            self.hands.connect()
        except BaseException:
            self.close()
            raise

    def _device(self, side: str, hand_id: int):
        if self.link == "pty":  # the device's own thread on a pseudo-terminal / virtual CAN channel
            return start_simulated_hand(self.transport, side, hand_id=hand_id, model=self.fingers[side], pace=False)
        cls = SimulatedSerialHand if self.transport == "serial" else SimulatedModbusHand
        device = cls(side, hand_id, model=self.fingers[side], pace=False)  # not started: served in-process
        name = f"{self.transport}-{side}-{id(self):x}"
        register_device(name, device)
        self._names.append(name)
        return device

    def _bus_kwargs(self, device) -> dict:
        kwargs = device.bus_kwargs()
        if self.link == "direct":
            kwargs["port"] = device.link.path
        return kwargs

    def _rad(self, units: np.ndarray) -> np.ndarray:
        return self.closed_rad + units / UNITS_OPEN * (self.open_rad - self.closed_rad)

    def measured_units(self) -> np.ndarray:
        q = self.world.hand_joint_pos()
        return UNITS_OPEN * (q - self.closed_rad) / (self.open_rad - self.closed_rad)

    def _measure(self) -> tuple[np.ndarray, np.ndarray]:
        angles = self.measured_units()
        forces = self.world.finger_forces_n() * GRAMS_PER_NEWTON
        left, right = self.fingers["left"], self.fingers["right"]
        left.set_measured(angles[:DOF], forces[:DOF])
        right.set_measured(angles[DOF:], forces[DOF:])
        return angles, forces

    def commanded_units(self) -> np.ndarray:
        return np.concatenate([self.fingers[s].commanded_angles for s in HAND_SIDES]).astype(np.float64)

    def update(self, t: float) -> None:
        angles, forces = self._measure()
        left, right = self.fingers["left"], self.fingers["right"]
        # the register arrays are replaced whole on every write, so reading them needs no lock
        target = np.concatenate([left.angle_set, right.angle_set])
        speed = np.concatenate([left.speed_set, right.speed_set])
        force_set = np.concatenate([left.force_set, right.force_set])
        max_step = np.clip(speed, 0, 1000) * (self.dt / FULL_STROKE_S)  # units: 1000 per full stroke
        step = np.clip(target - self.setpoint, -max_step, max_step)
        at_force_limit = (step < 0) & (forces >= force_set)
        # a finger pressing at its force limit holds where it is instead of winding the set-point further in
        self.setpoint = np.where(at_force_limit, np.maximum(self.setpoint, angles), self.setpoint + step)
        self.world.set_hand_targets(self._rad(self.setpoint))

    def close(self) -> None:
        try:
            if self.hands is not None:
                self.hands.close()
        finally:
            for device in self.devices:
                device.stop()
            self.devices = []
            for name in self._names:
                unregister_device(name)
            self._names = []

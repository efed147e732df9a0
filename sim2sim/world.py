"""The simulated robot world: MuJoCo, the motor drivers' PD loop, the gantry, pushes, and periodic listeners.

Time is simulation time and moves only in `advance_to(t)`, which the runtime's clock calls while the loop
"sleeps" (sim2sim.clock). Each PD update (pd_rate_hz):
    1. the LowCmd that is due (sent at least `actuator_latency_s` ago) becomes active,
    2. tau = kp' (q* - q) + kd' (dq* - dq) + tau_ff, clipped to the motor's effort limit (kp' = kp_scale * kp,
       kd' = kd_scale * kd: a gain mismatch between what the policy commands and what the drivers apply),
       held for the PD period (zero-order hold) while MuJoCo takes `substeps` physics steps,
    3. listeners whose period has elapsed run (simulated hands, mocap sampling).
Until the first command arrives the drivers output zero torque (a powered-down robot).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import mujoco
import numpy as np

from robot_hoi.utils.mujoco_model import with_body_mass
from sim2sim.layout import WorldLayout
from sim2sim.perturbations import Perturbation

GANTRY_SOLREF = (0.02, 1.0)


class Listener:
    def __init__(self, period_s: float, callback: Callable[[float], None]):
        self.period_s = period_s
        self.callback = callback
        self.next_t = 0.0


class SimWorld:
    def __init__(self, model: mujoco.MjModel, layout: WorldLayout, perturbation: Perturbation,
                 rng: np.random.Generator):
        self.layout = layout
        self.perturbation = perturbation
        self.physics = perturbation.physics
        self.physics.apply(model)
        self.model = model = self._perturbed(model)
        model.eq_solref[layout.gantry_eq] = GANTRY_SOLREF
        self.data = mujoco.MjData(model)
        self.rng = rng
        self.pd_dt = self.physics.pd_dt
        self.substeps = self.physics.substeps
        self.pd_ticks = 0
        n = len(layout.body_act)
        self._q_target = np.zeros(n)
        self._dq_target = np.zeros(n)
        self._kp = np.zeros(n)
        self._kd = np.zeros(n)
        self._tau_ff = np.zeros(n)
        self._pending: deque[tuple[float, tuple[np.ndarray, ...]]] = deque()
        self.commands_received = 0
        self.listeners: list[Listener] = []
        self.gantry_on = True
        self.gantry_released_at: float | None = None
        self._push_force = np.zeros(3)
        self._push_until = -1.0
        self._next_push: float | None = None
        self.pushes: list[tuple[float, list[float]]] = []
        self.torque_saturated_updates = 0

    # ------------------------------------------------------------------ set-up
    def _perturbed(self, m: mujoco.MjModel) -> mujoco.MjModel:
        p, lay = self.perturbation, self.layout
        if p.friction_scale != 1.0:
            m.geom_friction[lay.friction_geoms, 0] *= p.friction_scale
        if p.object_mass_scale != 1.0:
            m = with_body_mass(m, lay.object_body, p.object_mass_scale * float(m.body_mass[lay.object_body]))
        return m

    @property
    def t(self) -> float:
        return self.pd_ticks * self.pd_dt

    def reset(self, robot_qpos: np.ndarray, object_pos: np.ndarray, object_quat_wxyz: np.ndarray) -> None:
        """Robot at rest in `robot_qpos` (free base first) held by the gantry there; object at rest."""
        m, d, lay = self.model, self.data, self.layout
        mujoco.mj_resetData(m, d)
        d.qpos[: lay.robot_nq] = robot_qpos
        d.qpos[lay.object_qpos: lay.object_qpos + 3] = object_pos
        d.qpos[lay.object_qpos + 3: lay.object_qpos + 7] = object_quat_wxyz
        # weld world -> pelvis: relpose = the pelvis pose in the world frame
        m.eq_data[lay.gantry_eq, 0:3] = 0.0
        m.eq_data[lay.gantry_eq, 3:6] = robot_qpos[0:3]
        m.eq_data[lay.gantry_eq, 6:10] = robot_qpos[3:7]
        d.eq_active[lay.gantry_eq] = 1
        self.gantry_on = True
        mujoco.mj_forward(m, d)
        self.pd_ticks = 0
        for listener in self.listeners:
            listener.next_t = 0.0

    def add_listener(self, period_s: float, callback: Callable[[float], None]) -> None:
        """Call `callback(t)` every `period_s` of simulated time (at PD-update granularity), first at t = 0."""
        self.listeners.append(Listener(period_s, callback))

    def release_gantry(self) -> None:
        if self.gantry_on:
            self.data.eq_active[self.layout.gantry_eq] = 0
            self.gantry_on = False
            self.gantry_released_at = self.t
            if self.perturbation.push_dv > 0:
                self._next_push = self.t + self.rng.uniform(*self.perturbation.push_interval_s)

    # ------------------------------------------------------------------ the motor drivers
    def command(self, q, dq, kp, kd, tau) -> None:
        """A LowCmd for the body joints; it reaches the drivers after the actuator latency."""
        due = self.t + self.perturbation.actuator_latency_s
        self._pending.append((due, (np.array(q, float), np.array(dq, float), np.array(kp, float),
                                    np.array(kd, float), np.array(tau, float))))
        self.commands_received += 1

    def _take_due_commands(self) -> None:
        now = self.t + 1e-9
        while self._pending and self._pending[0][0] <= now:
            _, (q, dq, kp, kd, tau) = self._pending.popleft()
            p = self.perturbation
            self._q_target, self._dq_target, self._tau_ff = q, dq, tau
            self._kp, self._kd = kp * p.kp_scale, kd * p.kd_scale

    def _pd_torque(self) -> np.ndarray:
        d, lay = self.data, self.layout
        tau = self._kp * (self._q_target - d.qpos[lay.body_qpos])
        tau += self._kd * (self._dq_target - d.qvel[lay.body_dof])
        tau += self._tau_ff
        if (np.abs(tau) > lay.effort).any():
            self.torque_saturated_updates += 1
            np.minimum(tau, lay.effort, out=tau)
            np.maximum(tau, -lay.effort, out=tau)
        return tau

    # ------------------------------------------------------------------ pushes
    def _update_push(self) -> None:
        t = self.t
        p = self.perturbation
        if self._next_push is not None and t >= self._next_push:
            angle = self.rng.uniform(0.0, 2.0 * np.pi)
            direction = np.array([np.cos(angle), np.sin(angle), 0.0])
            self._push_force = self.layout.robot_mass * p.push_dv / p.push_duration_s * direction
            self._push_until = t + p.push_duration_s
            self._next_push = t + self.rng.uniform(*p.push_interval_s)
            self.pushes.append((t, (p.push_dv * direction).tolist()))
        self.data.xfrc_applied[self.layout.pelvis, 0:3] = self._push_force if t < self._push_until else 0.0

    # ------------------------------------------------------------------ stepping
    def advance_to(self, t_target: float) -> None:
        """Step PD updates until simulation time reaches t_target (never backwards)."""
        m, d, act, substeps, pd_dt = self.model, self.data, self.layout.body_act, self.substeps, self.pd_dt
        end_tick = int(np.ceil(t_target / pd_dt - 1e-6))
        listeners = self.listeners
        while self.pd_ticks < end_tick:
            t = self.pd_ticks * pd_dt
            if self._pending and self._pending[0][0] <= t + 1e-9:
                self._take_due_commands()
            for listener in listeners:
                if t >= listener.next_t - 1e-9:
                    listener.callback(t)
                    listener.next_t += listener.period_s
            if self._next_push is not None:
                self._update_push()
            d.ctrl[act] = self._pd_torque()
            mujoco.mj_step(m, d, nstep=substeps)
            self.pd_ticks += 1

    # ------------------------------------------------------------------ what sensors see
    def body_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, dq, pelvis quat wxyz, pelvis angular velocity in the pelvis frame), exact."""
        d, lay = self.data, self.layout
        return (d.qpos[lay.body_qpos].copy(), d.qvel[lay.body_dof].copy(), d.qpos[3:7].copy(),
                d.qvel[3:6].copy())

    def pelvis_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.data.qpos[0:3].copy(), self.data.qpos[3:7].copy()

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        a = self.layout.object_qpos
        return self.data.qpos[a: a + 3].copy(), self.data.qpos[a + 3: a + 7].copy()

    def object_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """(position, 3x3 rotation) of the object body from the last kinematics pass."""
        b = self.layout.object_body
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3).copy()

    def link_positions(self) -> np.ndarray:
        return self.layout.links.positions(self.data)

    def hand_contact(self) -> np.ndarray:
        """(2,) bool: left / right hand touches the object (training's contact_left_hand / right_hand)."""
        return self.data.sensordata[self.layout.hand_contact_adr] > 0

    def finger_forces_n(self) -> np.ndarray:
        """(12,) N: net contact force on each Inspire channel's finger chain (thumb counted for both)."""
        sd = self.data.sensordata
        adr = self.layout.finger_force_adr
        return np.sqrt(sd[adr] ** 2 + sd[adr + 1] ** 2 + sd[adr + 2] ** 2)

    def hand_joint_pos(self) -> np.ndarray:
        return self.data.qpos[self.layout.hand_qpos].copy()

    def set_hand_targets(self, rad: np.ndarray) -> None:
        self.data.ctrl[self.layout.hand_act] = rad

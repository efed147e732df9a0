"""The physics-backend contract: batched torch tensors in and out, no per-environment Python on the step path.

A backend owns `num_envs` copies of one compiled MuJoCo model. Controls are position targets for MuJoCo
position actuators, so the PD runs inside the physics step at the physics rate. Each `step` advances
`decimation` physics steps. Sensor values (link poses, contacts, ...) describe the state at the start of the
last physics sub-step, i.e. they lag the returned qpos by one physics step (< 5 ms); `set_state` recomputes them
exactly for the reset environments.

Implementations: `MujocoCpuBackend` (mujoco.rollout with a persistent thread pool, float64) and `MujocoWarpBackend`
(mujoco_warp worlds on a CUDA device or warp's CPU device, float32; tensors stay where the physics is).
`auto` picks warp on this process's CUDA device when there is one (robot_hoi/sim/device.py), else cpu.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import mujoco
import torch
from torch import Tensor

from robot_hoi.sim.device import resolve_physics
from robot_hoi.utils.mujoco_model import with_body_mass

# What a change of one body's mass changes in a compiled model (with_body_mass: the mass, the inertia and the
# constants mj_setConst derives from them); select_body_mass writes these rows.
MASS_FIELDS = ("body_mass", "body_subtreemass", "body_inertia", "body_invweight0", "dof_invweight0", "dof_M0")


class PhysicsBackend(ABC):
    model: mujoco.MjModel
    num_envs: int
    decimation: int
    device: torch.device

    @property
    def nq(self) -> int:
        return self.model.nq

    @property
    def nv(self) -> int:
        return self.model.nv

    @property
    def nu(self) -> int:
        return self.model.nu

    @property
    def control_dt(self) -> float:
        return self.model.opt.timestep * self.decimation

    @abstractmethod
    def step(self, ctrl: Tensor, wrench: Tensor | None = None) -> None:
        """Advance every environment by one control step with position targets `ctrl` (num_envs, nu), or one target
        per physics sub-step (num_envs, decimation, nu): a delayed command takes effect within the step. `wrench`
        (num_envs, nbody, 6): world-frame force and torque at each body's centre of mass (MuJoCo's xfrc_applied),
        held over every physics sub-step of this control step; None applies none."""

    @abstractmethod
    def set_state(self, env_ids: Tensor, qpos: Tensor, qvel: Tensor) -> None:
        """Overwrite the state of `env_ids` and recompute their sensors."""

    @abstractmethod
    def write_model_fields(self, env_ids: Tensor, values: dict[str, Tensor]) -> None:
        """Give the environments `env_ids` their own rows of MjModel arrays, from their next step: values[name] is
        (len(env_ids), *model.<name>.shape). Fields: MASS_FIELDS and the backend's `variable_fields` (named when it
        was made: the GPU backend gives them a row per world before it captures its graphs). Every environment
        starts with the model's own values. No host sync where the physics runs on a GPU."""

    def set_body_mass_levels(self, body_id: int, masses: list[float]) -> None:
        """Prepare the masses (kg) body `body_id` may take (inertia scaled alike, derived constants recomputed:
        utils.mujoco_model.with_body_mass). Once, before `select_body_mass`; one body per backend."""
        variants = [with_body_mass(self.model, body_id, float(kg)) for kg in masses]
        self._mass_levels = {name: torch.stack([torch.as_tensor(getattr(v, name)) for v in variants]).to(self.device)
                             for name in self.mass_fields}

    def select_body_mass(self, env_ids: Tensor, levels: Tensor) -> None:
        """Give the environments `env_ids` the prepared masses `levels` (indices into set_body_mass_levels'
        list), from their next step."""
        levels = levels.to(self.device)
        self.write_model_fields(env_ids, {name: rows[levels] for name, rows in self._mass_levels.items()})

    @property
    def mass_fields(self) -> tuple[str, ...]:
        return MASS_FIELDS

    # Each backend's __init__ sets these to tensors viewing the physics' own buffers: read without a copy.
    _qpos_t: Tensor
    _qvel_t: Tensor
    _sens_t: Tensor

    @property
    def qpos(self) -> Tensor:
        """(num_envs, nq) view of the current positions (the backend's dtype and device)."""
        return self._qpos_t

    @property
    def qvel(self) -> Tensor:
        """(num_envs, nv) view of the current velocities."""
        return self._qvel_t

    @property
    def sensordata(self) -> Tensor:
        """(num_envs, nsensordata) view of the latest sensor readings."""
        return self._sens_t

    def physics_report(self) -> dict[str, float]:
        """Scalars on the physics' health since the last call (overflow flags, buffer use; one host sync), for the
        runner to log every few iterations. Raises a UserError naming the buffer to raise when one overflowed."""
        return {}


def make_backend(name: str, model: mujoco.MjModel, num_envs: int, decimation: int, **kwargs) -> PhysicsBackend:
    name, device = resolve_physics(name, kwargs.pop("device", None))
    if name == "cpu":
        # the backends subclass PhysicsBackend from this module: imported here, not at the top (a cycle)
        from robot_hoi.sim.mujoco_cpu import MujocoCpuBackend

        return MujocoCpuBackend(model, num_envs, decimation, **kwargs)
    from robot_hoi.sim.warp_backend import MujocoWarpBackend  # a cycle too; it needs the warp extra to run

    return MujocoWarpBackend(model, num_envs, decimation, device=device, **kwargs)

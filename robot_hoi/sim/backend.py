"""The physics-backend contract: batched torch tensors in and out, no per-environment Python on the step path.

A backend owns `num_envs` copies of one compiled MuJoCo model. Controls are position targets for MuJoCo
position actuators, so the PD runs inside the physics step at the physics rate. Each `step` advances
`decimation` physics steps. Sensor values (link poses, contacts, ...) describe the state at the start of the
last physics sub-step, i.e. they lag the returned qpos by one physics step (< 5 ms); `set_state` recomputes them
exactly for the reset environments.

Implementations: `MujocoCpuBackend` (mujoco.rollout with a persistent thread pool). A MuJoCo Warp backend plugs in
behind the same interface (tensors stay on the GPU).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import mujoco
import torch
from torch import Tensor


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
    def step(self, ctrl: Tensor) -> None:
        """Advance every environment by one control step with position targets `ctrl` (num_envs, nu)."""

    @abstractmethod
    def set_state(self, env_ids: Tensor, qpos: Tensor, qvel: Tensor) -> None:
        """Overwrite the state of `env_ids` and recompute their sensors."""

    @property
    @abstractmethod
    def qpos(self) -> Tensor:
        """(num_envs, nq) float64 view of the current positions."""

    @property
    @abstractmethod
    def qvel(self) -> Tensor:
        """(num_envs, nv) float64 view of the current velocities."""

    @property
    @abstractmethod
    def sensordata(self) -> Tensor:
        """(num_envs, nsensordata) float64 view of the latest sensor readings."""


def make_backend(name: str, model: mujoco.MjModel, num_envs: int, decimation: int, **kwargs) -> PhysicsBackend:
    if name == "cpu":
        from robot_hoi.sim.mujoco_cpu import MujocoCpuBackend

        return MujocoCpuBackend(model, num_envs, decimation, **kwargs)
    if name == "warp":
        from robot_hoi.errors import UserError

        raise UserError("the MuJoCo Warp backend is not built yet; use --backend cpu")
    from robot_hoi.errors import UserError

    raise UserError(f"unknown physics backend {name!r} (choose cpu or warp)")

"""CPU physics backend: every environment stepped in C by `mujoco.rollout` on a persistent thread pool.

Per control step: one rollout call of `decimation` physics steps for all environments. The state and sensor
arrays are numpy buffers shared (zero-copy) with the torch views the environment reads.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
import torch
from mujoco import rollout
from torch import Tensor

from robot_hoi.sim.backend import PhysicsBackend
from robot_hoi.utils.mujoco_model import with_body_mass

_STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS.value
_CTRL_SPEC = mujoco.mjtState.mjSTATE_CTRL.value


def _state_slice(model: mujoco.MjModel, component: mujoco.mjtState) -> slice:
    """Where `component` sits inside the FULLPHYSICS state vector (components are stored in bit order)."""
    start = 0
    for bit in range(mujoco.mjtState.mjNSTATE.value if hasattr(mujoco.mjtState, "mjNSTATE") else 32):
        flag = 1 << bit
        if flag > _STATE_SPEC:
            break
        if not (_STATE_SPEC & flag):
            continue
        size = mujoco.mj_stateSize(model, flag)
        if flag == component.value:
            return slice(start, start + size)
        start += size
    raise ValueError(f"{component} is not part of the full physics state")


class MujocoCpuBackend(PhysicsBackend):
    def __init__(self, model: mujoco.MjModel, num_envs: int, decimation: int, nthread: int | None = None):
        self.model = model
        self.num_envs = num_envs
        self.decimation = decimation
        self.device = torch.device("cpu")
        self.nthread = nthread or min(os.cpu_count() or 1, num_envs)
        self._pool = rollout.Rollout(nthread=self.nthread)
        self._datas = [mujoco.MjData(model) for _ in range(self.nthread)]
        # A zero-timestep twin computes sensors of a given state without advancing it (used on reset).
        self._kin_model = _zero_timestep_copy(model)
        self._models = [model] * num_envs  # rollout's fast path takes one model per environment
        self._kin_models = [self._kin_model] * num_envs
        self._mass_levels: list[tuple[mujoco.MjModel, mujoco.MjModel]] = []  # set_body_mass_levels

        self.nstate = mujoco.mj_stateSize(model, _STATE_SPEC)
        self._qpos_slice = _state_slice(model, mujoco.mjtState.mjSTATE_QPOS)
        self._qvel_slice = _state_slice(model, mujoco.mjtState.mjSTATE_QVEL)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        initial = np.empty(self.nstate)
        mujoco.mj_getState(model, data, initial, _STATE_SPEC)
        self._state = np.tile(initial, (num_envs, 1))
        self._sensordata = np.tile(data.sensordata, (num_envs, 1))
        self._ctrl = np.zeros((num_envs, decimation, model.nu))
        self._ctrl_t = torch.from_numpy(self._ctrl)  # the step writes controls through this view: no temporaries
        self._ctrl_wrench: np.ndarray | None = None  # allocated on the first step with wrenches
        self._state_out = np.zeros((num_envs, decimation, self.nstate))
        self._sens_out = np.zeros((num_envs, decimation, model.nsensordata))
        self._qpos_t = torch.from_numpy(self._state[:, self._qpos_slice])
        self._qvel_t = torch.from_numpy(self._state[:, self._qvel_slice])
        self._sens_t = torch.from_numpy(self._sensordata)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    # ---- stepping ---------------------------------------------------------------------------------------------
    def step(self, ctrl: Tensor, wrench: Tensor | None = None) -> None:
        self._ctrl_t.copy_(ctrl.detach()[:, None, :])  # converted to float64 and held over the sub-steps in one copy
        control, spec = self._ctrl, _CTRL_SPEC
        # Once wrenches were applied they are always passed (zeros when None): the pool's MjData keep
        # xfrc_applied between calls, and a stale one would keep pushing.
        if wrench is not None or self._ctrl_wrench is not None:  # controls and wrenches, held over the sub-steps
            if self._ctrl_wrench is None:
                self._ctrl_wrench = np.zeros((self.num_envs, self.decimation, self.model.nu + 6 * self.model.nbody))
            self._ctrl_wrench[:, :, : self.model.nu] = self._ctrl
            if wrench is None:
                self._ctrl_wrench[:, :, self.model.nu:] = 0.0
            else:
                torch.from_numpy(self._ctrl_wrench[:, :, self.model.nu:]).copy_(
                    wrench.detach().reshape(self.num_envs, 1, -1))
            control, spec = self._ctrl_wrench, _CTRL_SPEC | mujoco.mjtState.mjSTATE_XFRC_APPLIED.value
        self._pool.rollout(
            self._models, self._datas, self._state, control, control_spec=spec,
            skip_checks=True, nstep=self.decimation, state=self._state_out, sensordata=self._sens_out,
        )
        self._state[:] = self._state_out[:, -1]
        self._sensordata[:] = self._sens_out[:, -1]

    def set_state(self, env_ids: Tensor, qpos: Tensor, qvel: Tensor) -> None:
        ids = env_ids.cpu().numpy()
        if ids.size == 0:
            return
        state = self._state[ids]
        state[:, self._qpos_slice] = qpos.detach().cpu().numpy()
        state[:, self._qvel_slice] = qvel.detach().cpu().numpy()
        self._state[ids] = state
        # One zero-length step evaluates the sensors of exactly this state.
        ctrl = self._ctrl[ids, :1].copy()
        state_out = np.zeros((ids.size, 1, self.nstate))
        sens_out = np.zeros((ids.size, 1, self.model.nsensordata))
        self._pool.rollout(
            [self._kin_models[i] for i in ids], self._datas, np.ascontiguousarray(state), ctrl,
            skip_checks=True, nstep=1, state=state_out, sensordata=sens_out,
        )
        self._sensordata[ids] = sens_out[:, 0]

    def set_body_mass_levels(self, body_id: int, masses: list[float]) -> None:
        """One model copy (and its zero-timestep twin) per mass, shared by the envs that have it."""
        self._mass_levels = [(variant, _zero_timestep_copy(variant))
                             for variant in (with_body_mass(self.model, body_id, float(kg)) for kg in masses)]

    def select_body_mass(self, env_ids: Tensor, levels: Tensor) -> None:
        for i, level in zip(env_ids.tolist(), levels.tolist(), strict=True):  # resets only
            self._models[i], self._kin_models[i] = self._mass_levels[level]


def _zero_timestep_copy(model: mujoco.MjModel) -> mujoco.MjModel:
    import copy

    twin = copy.copy(model)
    twin.opt.timestep = 0.0
    return twin

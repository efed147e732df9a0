"""CPU physics backend: every environment stepped in C by `mujoco.rollout` on a persistent thread pool.

Per control step: one rollout call of `decimation` physics steps for all environments. The state and sensor
arrays are numpy buffers shared (zero-copy) with the torch views the environment reads. Environments share the
model until one gets its own values (write_model_fields: domain randomisation); from then on each steps its own
copy (rollout takes one model per environment).
"""

from __future__ import annotations

import copy
import os

import mujoco
import numpy as np
import torch
from mujoco import rollout
from torch import Tensor

from robot_hoi.sim.backend import PhysicsBackend

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
    def __init__(self, model: mujoco.MjModel, num_envs: int, decimation: int, nthread: int | None = None,
                 variable_fields: tuple[str, ...] = ()):
        del variable_fields  # any field may vary: an environment's own model copy is made when it first does
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
        self._own_models = False  # True once every environment has its own copies (write_model_fields)

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
        # converted to float64 (and held over the sub-steps) in one copy
        self._ctrl_t.copy_(ctrl.detach() if ctrl.dim() == 3 else ctrl.detach()[:, None, :])
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

    def write_model_fields(self, env_ids: Tensor, values: dict[str, Tensor]) -> None:
        """Into each environment's own model copy and its zero-timestep twin (made on the first call)."""
        if not self._own_models:
            self._models = [copy.copy(self.model) for _ in range(self.num_envs)]
            self._kin_models = [_zero_timestep_copy(m) for m in self._models]
            self._own_models = True
        rows = {name: value.detach().cpu().numpy() for name, value in values.items()}
        for k, i in enumerate(env_ids.tolist()):  # resets only: one C model per environment, no batched write
            for name, value in rows.items():
                getattr(self._models[i], name)[...] = value[k]
                getattr(self._kin_models[i], name)[...] = value[k]


def _zero_timestep_copy(model: mujoco.MjModel) -> mujoco.MjModel:
    twin = copy.copy(model)
    twin.opt.timestep = 0.0
    return twin

"""MuJoCo Warp backend: all environments as `nworld` worlds of one `mujoco_warp` model, on a GPU or warp's CPU device.

The state lives in warp arrays; `qpos`, `qvel`, `sensordata` and the control buffer are torch views of them
(`wp.to_torch`, zero-copy on either device), so the environment's torch code runs unchanged where the physics is.
Warp computes in float32 (the CPU backend in float64): parity with the CPU backend is to float32 round-off
growing through contacts, measured in tests/sim/test_warp_backend.py.

On CUDA (with warp's memory pool) one control step and one forward pass are captured into CUDA graphs and replayed.
Kernels are compiled on first use (tens of seconds on the CPU device) and cached by warp under ~/.cache/warp.
"""

from __future__ import annotations

import mujoco
import numpy as np
import torch
from torch import Tensor

from robot_hoi.errors import UserError
from robot_hoi.sim.backend import PhysicsBackend

# Per-world capacities. Contacts are pooled across worlds (one world may exceed this); constraint rows are not:
# pyramidal condim-3 contacts take 4 rows each, plus joint limits and the hands' mimic equalities.
CONTACTS_PER_WORLD = 96
EXTRA_CONSTRAINT_ROWS = 160


def _import_warp():
    try:
        import warp

        warp.config.quiet = True  # before mujoco_warp initialises warp
        warp.config.log_level = warp.LOG_WARNING  # no per-module load lines
        import mujoco_warp
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise UserError("the warp backend needs mujoco-warp and warp-lang: pip install -e '.[warp]'") from exc
    warp.init()
    return warp, mujoco_warp


def cuda_available() -> bool:
    """The `auto` choice: mujoco-warp installed and a CUDA device torch can share tensors on (zero-copy views
    need torch's CUDA too). Decided without importing warp, which costs seconds on CPU-only machines."""
    import importlib.util

    return importlib.util.find_spec("mujoco_warp") is not None and torch.cuda.is_available()


class MujocoWarpBackend(PhysicsBackend):
    def __init__(self, model: mujoco.MjModel, num_envs: int, decimation: int, device: str | None = None,
                 nthread: int | None = None):
        del nthread  # the CPU backend's knob; warp parallelises over worlds itself
        wp, mjw = _import_warp()
        self._wp, self._mjw = wp, mjw
        if device is None:
            device = "cuda:0" if wp.is_cuda_available() else "cpu"
        try:
            self._wp_device = wp.get_device(device)
        except (RuntimeError, ValueError) as exc:
            raise UserError(f"warp backend: no device {device!r} ({exc})") from exc
        self.model = model
        self.num_envs = num_envs
        self.decimation = decimation
        self.device = torch.device(wp.device_to_torch(self._wp_device))

        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        with wp.ScopedDevice(self._wp_device):
            self._m = mjw.put_model(model)
            self._d = mjw.put_data(model, data, nworld=num_envs, nconmax=CONTACTS_PER_WORLD,
                                   njmax=4 * CONTACTS_PER_WORLD + EXTRA_CONSTRAINT_ROWS)
        self._qpos_t = wp.to_torch(self._d.qpos)
        self._qvel_t = wp.to_torch(self._d.qvel)
        self._ctrl_t = wp.to_torch(self._d.ctrl)
        self._sens_t = wp.to_torch(self._d.sensordata)
        # CUDA graphs of one control step and of one forward pass, replayed instead of launching kernel by kernel.
        self._step_graph = self._forward_graph = None
        if self._wp_device.is_cuda and wp.is_mempool_enabled(self._wp_device):
            with wp.ScopedDevice(self._wp_device):
                with wp.ScopedCapture() as capture:
                    self._physics_steps()
                self._step_graph = capture.graph
                with wp.ScopedCapture() as capture:
                    mjw.forward(self._m, self._d)
                self._forward_graph = capture.graph

    # ---- stepping ---------------------------------------------------------------------------------------------
    def _physics_steps(self) -> None:
        for _ in range(self.decimation):
            self._mjw.step(self._m, self._d)

    def step(self, ctrl: Tensor) -> None:
        self._ctrl_t.copy_(ctrl.detach())
        with self._wp.ScopedDevice(self._wp_device):
            if self._step_graph is not None:
                self._wp.capture_launch(self._step_graph)
            else:
                self._physics_steps()

    def set_state(self, env_ids: Tensor, qpos: Tensor, qvel: Tensor) -> None:
        if env_ids.numel() == 0:
            return
        ids = env_ids.to(self.device)
        self._qpos_t[ids] = qpos.to(self.device, self._qpos_t.dtype)
        self._qvel_t[ids] = qvel.to(self.device, self._qvel_t.dtype)
        # Sensors of exactly the new states: one forward pass over all worlds, the others' readings put back
        # (they keep their one-sub-step lag, as on the CPU backend).
        kept = self._sens_t.clone()
        with self._wp.ScopedDevice(self._wp_device):
            if self._forward_graph is not None:
                self._wp.capture_launch(self._forward_graph)
            else:
                self._mjw.forward(self._m, self._d)
        reset = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        reset[ids] = True
        self._sens_t[~reset] = kept[~reset]

    # ---- views ------------------------------------------------------------------------------------------------
    @property
    def qpos(self) -> Tensor:
        return self._qpos_t

    @property
    def qvel(self) -> Tensor:
        return self._qvel_t

    @property
    def sensordata(self) -> Tensor:
        return self._sens_t

    def contact_overflow(self) -> bool:
        """True when some world needed more contacts/constraints than allocated (results are then degraded)."""
        d = self._d
        ncon = int(np.asarray(d.nacon.numpy()).ravel()[0]) if hasattr(d, "nacon") else 0
        naconmax = int(getattr(d, "naconmax", 0) or 0)
        return bool(naconmax and ncon >= naconmax)

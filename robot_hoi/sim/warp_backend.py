"""MuJoCo Warp backend: all environments as `nworld` worlds of one `mujoco_warp` model, on a GPU or warp's CPU device.

The state lives in warp arrays; `qpos`, `qvel`, `sensordata` and the control buffer are torch views of them
(`wp.to_torch`, zero-copy on either device), so the environment's torch code runs unchanged where the physics is.
The views alias the live physics memory: whoever keeps a value across a step must copy it. Warp computes in
float32 (the CPU backend in float64): parity with the CPU backend is to float32 round-off growing through
contacts, measured in tests/sim/test_warp_backend.py.

On CUDA (with warp's memory pool) one control step and one forward pass are captured into CUDA graphs after a
warm-up step that compiles the kernels (minutes on a first run, then cached by warp under ~/.cache/warp). Without
conditional graph nodes (a CUDA < 12.4 driver) the solver's iterations are unrolled into the graph instead.
`physics_report()` reads mujoco_warp's sticky per-world overflow flags and buffer use (one host sync), and names
the buffer to raise when one overflowed.
"""

from __future__ import annotations

import mujoco
import numpy as np
import torch
from torch import Tensor

from robot_hoi.errors import UserError
from robot_hoi.sim.backend import MASS_FIELDS, PhysicsBackend
from robot_hoi.sim.device import import_warp, resolve_physics

# Per-world capacities. Contacts are pooled across worlds (one world may exceed this); constraint rows are not:
# pyramidal condim-3 contacts take 4 rows each, plus joint limits and the hands' mimic equalities.
CONTACTS_PER_WORLD = 96
EXTRA_CONSTRAINT_ROWS = 160
CONSTRAINT_ROWS = 4 * CONTACTS_PER_WORLD + EXTRA_CONSTRAINT_ROWS


def _overflow_buffers(mjw) -> dict[int, str]:
    """Overflow bits of a too-small buffer -> what to raise (robot_hoi/sim/warp_backend.py)."""
    kind = mjw.OverflowType
    rows = f"constraint rows per world (njmax {CONSTRAINT_ROWS}): raise EXTRA_CONSTRAINT_ROWS"
    contacts = f"contacts (nconmax {CONTACTS_PER_WORLD} per world): raise CONTACTS_PER_WORLD"
    return {int(kind.NEFC): rows, int(kind.NJMAX_NNZ): rows, int(kind.BROADPHASE): contacts,
            int(kind.NARROWPHASE): contacts, int(kind.CCD): contacts}


class MujocoWarpBackend(PhysicsBackend):
    def __init__(self, model: mujoco.MjModel, num_envs: int, decimation: int, device: str | None = None,
                 nthread: int | None = None, variable_fields: tuple[str, ...] = ()):
        del nthread  # the CPU backend's knob; warp parallelises over worlds itself
        wp, mjw = import_warp()
        self._wp, self._mjw = wp, mjw
        device = device or resolve_physics("warp", None)[1]
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
            self._batch_fields(model, num_envs, variable_fields)
            self._d = mjw.put_data(model, data, nworld=num_envs, nconmax=CONTACTS_PER_WORLD, njmax=CONSTRAINT_ROWS)
        view = wp.to_torch
        self._qpos_t, self._qvel_t = view(self._d.qpos), view(self._d.qvel)
        self._ctrl_t, self._sens_t = view(self._d.ctrl), view(self._d.sensordata)
        self._xfrc_t = view(self._d.xfrc_applied)  # (nworld, nbody, 6) spatial vectors
        self._wrench_applied = False
        self._overflow_t, self._nefc_t, self._nacon_t = view(self._d.overflow), view(self._d.nefc), view(self._d.nacon)
        self._contact_world_t = view(self._d.contact.worldid)
        self._buffer_bits = _overflow_buffers(mjw)
        self.high_water = {"constraint_rows": 0, "contacts_per_world": 0}
        self._step_graph = self._forward_graph = self._substep_graph = None
        self.stepping = self._capture_graphs()

    @property
    def mass_fields(self) -> tuple[str, ...]:
        return tuple(name for name in MASS_FIELDS if hasattr(self._m, name))  # MJWarp has no dof_M0

    def _batch_fields(self, model: mujoco.MjModel, num_envs: int, variable_fields: tuple[str, ...]) -> None:
        """Give the mass fields and `variable_fields` one row per world before any graph is captured (MJWarp reads
        a field with a leading world axis per world; later writes are in place)."""
        wp = self._wp
        self._field_views: dict[str, Tensor] = {}
        for name in dict.fromkeys((*self.mass_fields, *variable_fields)):
            field = getattr(self._m, name)
            rows = np.repeat(np.asarray(getattr(model, name), dtype=np.float32)[None], num_envs, axis=0)
            setattr(self._m, name, wp.array(rows, dtype=field.dtype))
            self._field_views[name] = wp.to_torch(getattr(self._m, name))

    def write_model_fields(self, env_ids: Tensor, values: dict[str, Tensor]) -> None:
        ids = env_ids.to(self.device)
        for name, value in values.items():
            if name not in self._field_views:
                raise ValueError(f"model field {name} was not named in variable_fields when the backend was made")
            view = self._field_views[name]
            view[ids] = value.to(self.device, view.dtype).reshape(view[ids].shape)

    # ---- CUDA graphs ------------------------------------------------------------------------------------------
    def _capture_graphs(self) -> str:
        """Capture one control step and one forward pass (CUDA with warp's memory pool); returns how steps run."""
        wp, mjw, device = self._wp, self._mjw, self._wp_device
        if not device.is_cuda:
            return "kernel launches (warp's CPU device)"
        if not wp.is_mempool_enabled(device):
            return "kernel launches (CUDA graphs need warp's memory pool)"
        conditional = wp.is_conditional_graph_supported()
        if not conditional:
            self._m.opt.graph_conditional = False  # the solver's while loop becomes a fixed unrolled count
        print(f"[warp] compiling MuJoCo Warp kernels for {device} (minutes on a first run; cached by warp)",
              flush=True)
        with wp.ScopedDevice(device):
            self._physics_steps()  # warm-up: every kernel of a step compiled and loaded before capture
            mjw.forward(self._m, self._d)
            wp.synchronize_device(device)
            try:
                with wp.ScopedCapture() as capture:
                    self._physics_steps()
                step_graph = capture.graph
                with wp.ScopedCapture() as capture:
                    mjw.step(self._m, self._d)
                substep_graph = capture.graph
                with wp.ScopedCapture() as capture:
                    mjw.forward(self._m, self._d)
                self._step_graph, self._forward_graph = step_graph, capture.graph
                self._substep_graph = substep_graph
            except Exception as exc:  # noqa: BLE001 - any capture failure leaves plain launches, which work
                print(f"[warp] CUDA graph capture failed ({type(exc).__name__}: {exc}); launching kernels instead",
                      flush=True)
            mjw.reset_data(self._m, self._d)  # undo the warm-up step (the env sets every world's state next)
            mjw.forward(self._m, self._d)
        if self._step_graph is None:
            return "kernel launches (graph capture failed)"
        return "CUDA graph" if conditional else "CUDA graph (solver unrolled: no conditional graph nodes, CUDA < 12.4)"

    # ---- stepping ---------------------------------------------------------------------------------------------
    def _physics_steps(self) -> None:
        for _ in range(self.decimation):
            self._mjw.step(self._m, self._d)

    def step(self, ctrl: Tensor, wrench: Tensor | None = None) -> None:
        per_substep = ctrl.dim() == 3  # one target per sub-step (a delayed command): one launch per sub-step
        self._ctrl_t.copy_(ctrl.detach()[:, 0] if per_substep else ctrl.detach())
        if wrench is not None or self._wrench_applied:  # xfrc_applied persists in the worlds: clear it once
            if wrench is None:
                self._xfrc_t.zero_()
            else:
                self._xfrc_t.copy_(wrench.detach().reshape(self._xfrc_t.shape))
            self._wrench_applied = wrench is not None
        with self._wp.ScopedDevice(self._wp_device):
            if per_substep:
                for j in range(self.decimation):
                    if j:
                        self._ctrl_t.copy_(ctrl.detach()[:, j])
                    if self._substep_graph is not None:
                        self._wp.capture_launch(self._substep_graph)
                    else:
                        self._mjw.step(self._m, self._d)
            elif self._step_graph is not None:
                self._wp.capture_launch(self._step_graph)
            else:
                self._physics_steps()

    def _forward(self) -> None:
        with self._wp.ScopedDevice(self._wp_device):
            if self._forward_graph is not None:
                self._wp.capture_launch(self._forward_graph)
            else:
                self._mjw.forward(self._m, self._d)

    def set_state(self, env_ids: Tensor, qpos: Tensor, qvel: Tensor) -> None:
        if env_ids.numel() == 0:
            return
        ids = env_ids.to(self.device)
        self._qpos_t[ids] = qpos.to(self.device, self._qpos_t.dtype)
        self._qvel_t[ids] = qvel.to(self.device, self._qvel_t.dtype)
        # Sensors of exactly the new states: one forward pass over all worlds, the others' readings put back
        # (they keep their one-sub-step lag, as on the CPU backend). Index writes only: no host sync.
        kept = self._sens_t.clone()
        self._forward()
        kept[ids] = self._sens_t[ids]
        self._sens_t.copy_(kept)


    # ---- health -----------------------------------------------------------------------------------------------
    def physics_report(self) -> dict[str, float]:
        """Worlds whose flags tripped since the last report, and buffer use now (one host sync); the flags are
        cleared. Raises a UserError naming the buffer to raise when a buffer overflowed (results are degraded)."""
        flags = self._overflow_t
        bits = sorted({*self._buffer_bits, int(self._mjw.OverflowType.ITERATIONS),
                       int(self._mjw.OverflowType.LS_ITERATIONS)})
        naconmax = self._contact_world_t.shape[0]
        live = (torch.arange(naconmax, device=self.device) < self._nacon_t[0]).to(torch.float32)
        per_world = torch.bincount(self._contact_world_t.clamp(0, self.num_envs - 1), weights=live,
                                   minlength=self.num_envs)
        counts = torch.stack([((flags & bit) != 0).sum() for bit in bits]
                             + [self._nefc_t.max(), per_world.max().long()]).tolist()
        flags.zero_()
        tripped = dict(zip(bits, counts[:len(bits)], strict=True))
        rows, contacts = int(counts[-2]), int(counts[-1])
        self.high_water["constraint_rows"] = max(self.high_water["constraint_rows"], rows)
        self.high_water["contacts_per_world"] = max(self.high_water["contacts_per_world"], contacts)
        for bit, advice in self._buffer_bits.items():
            if tripped[bit]:
                name = self._mjw.OverflowType(bit).name
                raise UserError(f"MuJoCo Warp overflow {name} in {tripped[bit]} of {self.num_envs} worlds: out of "
                                f"{advice} in robot_hoi/sim/warp_backend.py")
        kind = self._mjw.OverflowType
        return {"Physics/solver_iteration_limit_worlds": float(tripped[int(kind.ITERATIONS)]),
                "Physics/linesearch_limit_worlds": float(tripped[int(kind.LS_ITERATIONS)]),
                "Physics/constraint_rows_max": float(rows), "Physics/contacts_per_world_max": float(contacts)}

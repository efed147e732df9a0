"""The interaction scene for one embodiment and one object: compiled model, index layout, default state."""

from __future__ import annotations

import mujoco
import numpy as np
import torch

from robot_hoi.embodiment import build_robot_spec
from robot_hoi.sim import make_backend
from robot_hoi.sim.scene import OBJECT_BODY, OBJECT_JOINT, SceneLayout, add_task_object
from robot_hoi.termination import hand_link_groups

HAND_LINK_MARKERS = ("_tip", "hand_base")


class InteractionScene:
    def __init__(self, embodiment, object_asset, *, self_collision: bool = False, density: float = 25.0,
                 friction: float = 0.9, torsional_friction: float = 0.0, timestep: float | None = None,
                 object_collision: str = "hull", friction_cone: str = "pyramidal", impratio: float = 1.0):
        self.embodiment = embodiment
        self.object_asset = object_asset
        spec = build_robot_spec(embodiment, self_collision=self_collision, floor=True)
        contact_names = add_task_object(spec, embodiment, object_asset, density=density, friction=friction,
                                        torsional_friction=torsional_friction, object_collision=object_collision)
        if timestep is not None:
            spec.option.timestep = timestep
        spec.option.cone = getattr(mujoco.mjtCone, f"mjCONE_{friction_cone.upper()}")
        spec.option.impratio = impratio
        self.spec = spec
        self.model = spec.compile()
        self.layout = self._resolve_layout(contact_names)
        self.hand_contact_ids = [contact_names.index("left_hand"), contact_names.index("right_hand")]
        self.finger_contact_ids = [i for i, n in enumerate(contact_names) if n[:2] in ("L_", "R_")]
        self.body_link_ids = [i for i, n in enumerate(self.layout.link_names)
                              if not any(m in n for m in HAND_LINK_MARKERS)]
        # wrist + fingertip links of the left and right hand (for contact tolerance)
        self.hand_link_ids = hand_link_groups(self.layout.link_names)
        self.hand_link_flat_ids = self.hand_link_ids[0] + self.hand_link_ids[1]
        self.pelvis_body_id = int(self.model.jnt_bodyid[0])  # the free joint's body
        self.object_mass = float(self.model.body_mass[self.object_body_id()])
        self.feet_link_ids = [i for i, n in enumerate(self.layout.link_names) if "ankle" in n or "toe" in n]

    @classmethod
    def for_task(cls, embodiment, object_asset, env_cfg) -> InteractionScene:
        """The scene an InteractionEnvCfg describes (object physics, collision shape, friction model)."""
        return cls(embodiment, object_asset, self_collision=env_cfg.self_collision, density=env_cfg.object_density,
                   friction=env_cfg.object_friction, torsional_friction=env_cfg.object_torsional_friction,
                   object_collision=env_cfg.object_collision, friction_cone=env_cfg.friction_cone,
                   impratio=env_cfg.impratio)

    def _resolve_layout(self, contact_names: list[str]) -> SceneLayout:
        m = self.model
        names = list(self.embodiment.actuator_names)
        joint_ids = [m.actuator_trnid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n), 0] for n in names]
        obj_joint = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, OBJECT_JOINT)
        num_links = len(self.embodiment.link_map)
        contact_adr = m.sensor_adr[3 * num_links]
        return SceneLayout(
            link_names=list(self.embodiment.link_map),
            actuator_names=names,
            actuator_qpos=np.array([m.jnt_qposadr[j] for j in joint_ids]),
            actuator_dof=np.array([m.jnt_dofadr[j] for j in joint_ids]),
            robot_nq=int(m.jnt_qposadr[obj_joint]),
            robot_nv=int(m.jnt_dofadr[obj_joint]),
            object_qpos=int(m.jnt_qposadr[obj_joint]),
            object_dof=int(m.jnt_dofadr[obj_joint]),
            link_pos=slice(0, 3 * num_links),
            link_quat=slice(3 * num_links, 7 * num_links),
            link_vel=slice(7 * num_links, 10 * num_links),
            contact_names=contact_names,
            contact=slice(int(contact_adr), int(contact_adr) + 4 * len(contact_names)),
        )

    def make_backend(self, num_envs: int, backend: str = "cpu", nthread: int | None = None,
                     device: str | None = None, variable_fields: tuple[str, ...] = ()):
        """`variable_fields`: MjModel arrays each environment may get its own values of (domain randomisation)."""
        return make_backend(backend, self.model, num_envs, self.embodiment.decimation, nthread=nthread,
                            device=device, variable_fields=variable_fields)

    def actuator_ctrlrange(self) -> tuple[np.ndarray, np.ndarray]:
        ids = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in self.layout.actuator_names]
        rng = self.model.actuator_ctrlrange[ids]
        return rng[:, 0].copy(), rng[:, 1].copy()

    def default_robot_qpos(self) -> torch.Tensor:
        """Free base at the spawn height, every robot joint at its default (passive fingers follow the mimics)."""
        qpos = np.array(self.model.qpos0[: self.layout.robot_nq], dtype=np.float64)
        qpos[2] = self.embodiment.spawn_height
        qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
        qpos[self.layout.actuator_qpos] = self.embodiment.default_pos
        data = mujoco.MjData(self.model)
        data.qpos[: self.layout.robot_nq] = qpos
        mujoco.mj_forward(self.model, data)
        _satisfy_joint_equalities(self.model, data)
        return torch.as_tensor(data.qpos[: self.layout.robot_nq], dtype=torch.float32)[None]

    def object_body_id(self) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY)


def _satisfy_joint_equalities(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Put passive (mimic) joints where their joint-equality polynomials say, so resets start consistent."""
    for i in range(model.neq):
        if model.eq_type[i] != mujoco.mjtEq.mjEQ_JOINT:
            continue
        j1, j2 = model.eq_obj1id[i], model.eq_obj2id[i]
        c = model.eq_data[i]
        x = data.qpos[model.jnt_qposadr[j2]]
        data.qpos[model.jnt_qposadr[j1]] = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3 + c[4] * x**4

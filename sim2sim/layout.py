"""Index maps of the validation model, resolved once against the policy contract's names.

Everything the world, the simulated devices and the metrics read from MjData goes through these arrays, so no
per-step name lookups happen and a model that lacks a joint, link or sensor fails at load with its name.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from deploy.contract import PolicyContract
from deploy.hand_units import HAND_SIDES
from robot_hoi.embodiment.links import LinkIndex, resolve_links
from sim2sim.scene import GANTRY, PELVIS

OBJECT_BODY = "object"  # robot_hoi.sim.scene names; repeated here so workers need not import robot_hoi.sim
OBJECT_JOINT = "object_joint"
FLOOR_GEOM = "floor"
# Inspire channel -> the training scene's finger contact sensor (the thumb's two channels share one chain).
CHANNEL_SENSORS = ("pinky", "ring", "middle", "index", "thumb", "thumb")


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    i = mujoco.mj_name2id(model, kind, name)
    if i < 0:
        raise ValueError(f"validation model has no {kind.name[len('mjOBJ_'):].lower()} named {name!r}")
    return i


@dataclass(frozen=True)
class WorldLayout:
    body_act: np.ndarray  # (B,) actuator ids of the body motors, contract order
    body_qpos: np.ndarray  # (B,) qpos addresses of those joints
    body_dof: np.ndarray  # (B,) dof addresses
    effort: np.ndarray  # (B,) N m, motor torque limits
    hand_act: np.ndarray  # (12,) hand position actuators, left then right, channel order
    hand_qpos: np.ndarray  # (12,)
    pelvis: int  # body id
    object_body: int
    object_qpos: int  # free joint: pos (3) + quat wxyz (4)
    object_dof: int
    robot_nq: int  # qpos entries of the robot (free base + every robot joint)
    robot_nv: int
    links: LinkIndex  # the contract's link_names
    hand_contact_adr: np.ndarray  # (2,) sensordata address of left/right hand-object contact 'found'
    finger_force_adr: np.ndarray  # (12,) sensordata address of each channel's contact force xyz
    gantry_eq: int
    friction_geoms: np.ndarray  # floor, robot and object geoms (friction perturbations: a foot-floor contact takes
                                # the larger of its two geoms' friction, so the robot's scale with the floor's)
    robot_mass: float

    @classmethod
    def resolve(cls, model: mujoco.MjModel, contract: PolicyContract) -> WorldLayout:
        obj = mujoco.mjtObj
        n = contract.num_body
        names = contract.actuator_names
        act = np.array([_id(model, obj.mjOBJ_ACTUATOR, a) for a in names])
        joints = model.actuator_trnid[act, 0]
        body_act = act[:n]
        if np.any(model.actuator_biastype[body_act] != mujoco.mjtBias.mjBIAS_NONE):
            raise ValueError("the body actuators of the validation model must be plain motors (no built-in PD)")
        object_joint = _id(model, obj.mjOBJ_JOINT, OBJECT_JOINT)
        sensor_adr = {}
        for i in range(model.nsensor):
            sensor_adr[model.sensor(i).name] = int(model.sensor_adr[i])

        def sensor(name: str) -> int:
            if name not in sensor_adr:
                raise ValueError(f"validation model has no sensor named {name!r}")
            return sensor_adr[name]

        prefix = {"left": "L_", "right": "R_"}
        finger_force = [sensor(f"contact_{prefix[side]}{finger}") + 1 for side in HAND_SIDES
                        for finger in CHANNEL_SENSORS]
        pelvis = _id(model, obj.mjOBJ_BODY, PELVIS)
        object_body = _id(model, obj.mjOBJ_BODY, OBJECT_BODY)
        robot_bodies = [b for b in range(1, model.nbody) if model.body_rootid[b] == model.body_rootid[pelvis]]
        object_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == object_body]
        return cls(
            body_act=body_act,
            body_qpos=model.jnt_qposadr[joints[:n]].copy(),
            body_dof=model.jnt_dofadr[joints[:n]].copy(),
            effort=np.abs(model.actuator_ctrlrange[body_act]).max(axis=1),
            hand_act=act[n:].copy(),
            hand_qpos=model.jnt_qposadr[joints[n:]].copy(),
            pelvis=pelvis,
            object_body=object_body,
            object_qpos=int(model.jnt_qposadr[object_joint]),
            object_dof=int(model.jnt_dofadr[object_joint]),
            robot_nq=int(model.jnt_qposadr[object_joint]),
            robot_nv=int(model.jnt_dofadr[object_joint]),
            links=LinkIndex.from_refs(resolve_links(model, contract.link_names)),
            hand_contact_adr=np.array([sensor("contact_left_hand"), sensor("contact_right_hand")]),
            finger_force_adr=np.array(finger_force),
            gantry_eq=_id(model, obj.mjOBJ_EQUALITY, GANTRY),
            friction_geoms=np.array([_id(model, obj.mjOBJ_GEOM, FLOOR_GEOM), *object_geoms,
                                     *(g for g in range(model.ngeom) if model.geom_bodyid[g] in robot_bodies)]),
            robot_mass=float(model.body_mass[robot_bodies].sum()),
        )

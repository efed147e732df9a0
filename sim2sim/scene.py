"""The validation world's MuJoCo model, built once in the parent process and shipped to workers as MJB bytes.

It is the project's embodiment (robot_hoi.embodiment.build_robot_spec) with three changes for sim2sim:
    - the 29 body actuators are plain motors (gear 1, +-effort limit): the PD law runs outside MuJoCo, at the
      motor drivers' rate, on LowCmd-like targets (sim2sim.world); the hands keep their position servos,
    - robot self-collision is on by default (the real robot has no collision filter; training turns it off),
    - a gantry: a weld from the world to the pelvis that holds the robot while the runtime goes through
      ZERO_TORQUE and RAMP_TO_DEFAULT, released when the runtime reaches HOLD (as an operator lowers the robot).
The object and the contact sensors are added by the function training uses (robot_hoi.sim.scene.add_task_object),
on the same floor.

Workers load the bytes with `load_model` and never import robot_hoi.sim (which pulls in torch).
"""

from __future__ import annotations

import mujoco
import numpy as np

from robot_hoi.embodiment import build_robot_spec, load_embodiment

GANTRY = "sim2sim_gantry"
PELVIS = "pelvis"


def build_scene_bytes(embodiment: str, object_asset, *, self_collision: bool = True, density: float = 25.0,
                      friction: float = 0.9, torsional_friction: float = 0.0, object_collision: str = "hull") -> bytes:
    """Compile the validation scene for one object and return it as MJB bytes."""
    from robot_hoi.sim.scene import add_task_object

    cfg = load_embodiment(embodiment)
    spec = build_robot_spec(cfg, self_collision=self_collision, floor=True)
    hand_joints = {c.joint for hand in cfg.hands.values() for c in hand.channels}
    desc = cfg.description()
    for act in cfg.actuators:
        if act.name in hand_joints:
            continue
        effort = desc.joint(act.name).effort
        actuator = spec.actuator(act.name)
        actuator.set_to_motor()
        actuator.gear = [1.0, 0, 0, 0, 0, 0]
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.ctrlrange = [-effort, effort]
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-effort, effort]
    add_task_object(spec, cfg, object_asset, density=density, friction=friction,
                    torsional_friction=torsional_friction, object_collision=object_collision)
    spec.add_equality(name=GANTRY, type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
                      name1="world", name2=PELVIS, data=[0.0] * 3 + [0.0, 0.0, cfg.spawn_height, 1.0, 0.0, 0.0, 0.0]
                      + [1.0] + [0.0])
    model = spec.compile()
    return model_to_bytes(model)


def model_to_bytes(model) -> bytes:
    buffer = np.empty(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()


def load_model(blob: bytes):
    """MJB bytes -> mujoco.MjModel (through MuJoCo's in-memory asset loader; no file is written)."""
    return mujoco.MjModel.from_binary_path("scene.mjb", {"scene.mjb": blob})

"""Robot description + control config -> mujoco.MjSpec -> MjModel / self-contained MJCF file.

The model: free base `floating_base_joint` on the pelvis, hinge joints with armature/damping from the
description, one MuJoCo *position* actuator per EmbodimentConfig actuator (same name as its joint, kp/kv from the
config, forcerange = effort limit, ctrlrange = joint range), the hands' passive joints tied to their drivers by
joint equality constraints (URDF mimic ratios), integrator implicitfast, timestep = control_dt / decimation,
primitive collision geoms only (bits in robot_hoi.embodiment.collision) and a keyframe "default" (the default
pose standing on the floor).
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np

from deploy.atomic import atomic_write_text
from robot_hoi.embodiment.collision import (
    COLLISION_GROUP,
    SITE_GROUP,
    VISUAL_MESH_GROUP,
    robot_bits,
    set_world_collision,
)
from robot_hoi.embodiment.config import EmbodimentConfig
from robot_hoi.embodiment.spec_types import BodySpec, RobotDescription
from robot_hoi.errors import UserError
from robot_hoi.paths import shared_dir

DEFAULT_KEYFRAME = "default"
FLOOR_GEOM = "floor"
_ROBOT_RGBA = (0.55, 0.6, 0.68, 1.0)
_SITE_RGBA = (1.0, 0.2, 0.2, 1.0)
# Mimic couplings: stiffer than MuJoCo's default 0.02 s so a closing finger's passive joint lags < 0.01 rad;
# never below 2 physics steps (MuJoCo's own stability floor).
MIMIC_TIMECONST = 0.01


def unitree_mesh_dir() -> Path | None:
    """Unitree's STL folder in the reference data, or None on a machine without it."""
    root = shared_dir()
    path = None if root is None else root / "reference" / "robots" / "unitree_g1" / "meshes"
    return path if path is not None and path.is_dir() else None


def default_qpos(cfg: EmbodimentConfig, model_joint_names: list[str], spawn_height: float | None = None) -> np.ndarray:
    """qpos of the default stand: base at (0, 0, spawn_height), upright; actuated joints at their defaults and
    passive finger joints at their mimic values. `model_joint_names` = hinge joints in model order."""
    desc = cfg.description()
    hinge = {a.name: a.default for a in cfg.actuators}
    for j in desc.passive_joints:
        hinge[j.name] = j.mimic.multiplier * hinge[j.mimic.joint] + j.mimic.offset
    base = [0.0, 0.0, cfg.spawn_height if spawn_height is None else spawn_height, 1.0, 0.0, 0.0, 0.0]
    return np.array(base + [hinge[n] for n in model_joint_names], dtype=np.float64)


def _add_body(parent: mujoco.MjsBody, b: BodySpec, bits: tuple[int, int], mesh_dir: Path | None) -> mujoco.MjsBody:
    body = parent.add_body(name=b.name, pos=list(b.pos), quat=list(b.quat_wxyz))
    inertial = b.inertial
    body.explicitinertial = True
    body.mass = inertial.mass
    body.ipos = list(inertial.com)
    if inertial.full is not None:
        ixx, iyy, izz, ixy, ixz, iyz = inertial.full
        body.fullinertia = [ixx, iyy, izz, ixy, ixz, iyz]
    else:
        body.iquat = list(inertial.quat_wxyz)
        body.inertia = list(inertial.diag)
    if b.joint is not None:
        j = b.joint
        body.add_joint(
            name=j.name,
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=list(j.axis),
            range=list(j.range),
            # Passive finger joints follow their driver through the equality; their URDF ranges are narrower
            # than the mimic image of the driver's range, so enforcing both would make the solver fight itself.
            limited=mujoco.mjtLimited.mjLIMITED_FALSE if j.mimic else mujoco.mjtLimited.mjLIMITED_TRUE,
            armature=j.armature,
            damping=j.damping,
        )
    contype, conaffinity = bits
    for g in b.geoms:
        kwargs = dict(
            name=g.name,
            type=getattr(mujoco.mjtGeom, f"mjGEOM_{g.type.upper()}"),
            contype=contype,
            conaffinity=conaffinity,
            condim=3,
            group=COLLISION_GROUP,
            rgba=list(_ROBOT_RGBA),
            density=0.0,
        )
        if g.type == "capsule":
            body.add_geom(**kwargs, size=[g.size[0], 0.0, 0.0], fromto=list(g.fromto))
        else:
            body.add_geom(**kwargs, size=list(g.size) + [0.0] * (3 - len(g.size)), pos=list(g.pos),
                          quat=list(g.quat_wxyz))
    for s in b.sites:
        body.add_site(name=s.name, pos=list(s.pos), size=[0.006, 0.0, 0.0], group=SITE_GROUP, rgba=list(_SITE_RGBA))
    if mesh_dir is not None:
        for m in b.meshes:
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=m.file[:-4], pos=list(m.pos), rgba=list(m.rgba),
                          contype=0, conaffinity=0, group=VISUAL_MESH_GROUP, density=0.0)
    return body


def _add_floor(spec: mujoco.MjSpec) -> None:
    spec.add_texture(name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
                     rgb1=[0.2, 0.3, 0.4], rgb2=[0.1, 0.2, 0.3], width=300, height=300)
    spec.add_material(name="grid", textures=["", "grid"], texrepeat=[5, 5], texuniform=True, reflectance=0.1)
    floor = spec.worldbody.add_geom(name=FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 0.05],
                                    material="grid", condim=3)
    set_world_collision(floor)
    spec.worldbody.add_light(name="top", pos=[0.0, 0.0, 4.0], dir=[0.0, 0.0, -1.0],
                             type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)


def build_robot_spec(
    cfg: EmbodimentConfig,
    *,
    self_collision: bool | None = None,
    floor: bool = True,
    visual_meshes: bool = False,
    fixed_base: bool = False,
) -> mujoco.MjSpec:
    """The robot as an editable MjSpec (others add objects to it before compiling).

    self_collision: None = cfg.self_collision. visual_meshes: add Unitree's STL meshes (viewer only, no mass, no
    contacts) when the reference mesh folder exists; the resulting spec then refers to files outside the repo.
    fixed_base: weld the pelvis at spawn height (no free joint), e.g. to look at the robot or test the hands.
    """
    desc: RobotDescription = cfg.description()
    self_collision = cfg.self_collision if self_collision is None else self_collision
    spec = mujoco.MjSpec()
    spec.modelname = cfg.name
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    # AUTO: robot bodies carry explicit inertials (their geoms have density 0); objects others add to this spec
    # may still get their inertia from their geoms.
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    spec.option.timestep = cfg.physics_dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.stat.center = [0.0, 0.0, 0.7]
    spec.stat.extent = 1.0

    mesh_dir = unitree_mesh_dir() if visual_meshes else None
    if mesh_dir is not None:
        spec.meshdir = str(mesh_dir)
        for file in sorted({m.file for b in desc.bodies for m in b.meshes}):
            spec.add_mesh(name=file[:-4], file=file)
    if floor:
        _add_floor(spec)

    bits = robot_bits(self_collision)
    bodies: dict[str, mujoco.MjsBody] = {"world": spec.worldbody}
    for b in desc.bodies:
        bodies[b.name] = _add_body(bodies[b.parent], b, bits, mesh_dir)
    base = bodies[desc.bodies[0].name]
    base.pos = [0.0, 0.0, cfg.spawn_height]
    if not fixed_base:
        base.add_freejoint(name=desc.base_joint)

    for j in desc.passive_joints:
        spec.add_equality(
            name=f"{j.name}_mimic",
            type=mujoco.mjtEq.mjEQ_JOINT,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            name1=j.name,
            name2=j.mimic.joint,
            data=[j.mimic.offset, j.mimic.multiplier] + [0.0] * 10,
            solref=[max(MIMIC_TIMECONST, 2.0 * cfg.physics_dt), 1.0],
        )
    if self_collision:
        for a, b in desc.contact_excludes:
            spec.add_exclude(name=f"{a}__{b}", bodyname1=a, bodyname2=b)

    for act in cfg.actuators:
        joint = desc.joint(act.name)
        actuator = spec.add_actuator(name=act.name, target=act.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        actuator.set_to_position(kp=act.kp, kv=act.kd)
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.ctrlrange = list(joint.range)
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-joint.effort, joint.effort]

    hinge_names = [b.joint.name for b in desc.bodies if b.joint is not None]
    qpos = default_qpos(cfg, hinge_names)
    spec.add_key(name=DEFAULT_KEYFRAME, qpos=(qpos[7:] if fixed_base else qpos).tolist(),
                 ctrl=cfg.default_pos.tolist())
    return spec


def build_model(cfg: EmbodimentConfig, **kwargs) -> mujoco.MjModel:
    """Compile `build_robot_spec(cfg, **kwargs)`."""
    return build_robot_spec(cfg, **kwargs).compile()


def mjcf_text(cfg: EmbodimentConfig, **kwargs) -> str:
    """Self-contained MJCF (no mesh files) that plain MjModel.from_xml_path loads."""
    kwargs.setdefault("visual_meshes", False)
    spec = build_robot_spec(cfg, **kwargs)
    spec.compile()
    return spec.to_xml()


def write_mjcf(cfg: EmbodimentConfig, path: str | os.PathLike, **kwargs) -> Path:
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{path}: is a folder; give a file name such as g1_inspire.xml")
    atomic_write_text(path, mjcf_text(cfg, **kwargs))
    return path

"""The training/validation scene: robot + floor + the clip's object, with the sensors the tasks read.

Sensors are laid out in blocks so the environment slices them without per-link Python work:
link positions (L x 3), link quaternions wxyz (L x 4), link linear velocities (L x 3), then contact sensors
(C x [found, fx, fy, fz]). Link L follows the embodiment's `link_map` order.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import trimesh

from robot_hoi.embodiment.collision import world_bits

OBJECT_BODY = "object"
OBJECT_JOINT = "object_joint"
FINGERS = ("pinky", "ring", "middle", "index", "thumb")


@dataclass
class SceneLayout:
    """Index maps into qpos/qvel/sensordata of a compiled scene (resolved once)."""

    link_names: list[str]
    actuator_names: list[str]
    actuator_qpos: np.ndarray      # (A,) qpos address of each actuated joint
    actuator_dof: np.ndarray       # (A,) dof address of each actuated joint
    robot_nq: int                  # free base 7 + all robot joints (actuated + passive)
    robot_nv: int
    object_qpos: int               # address of the object's free joint (pos 3 + quat wxyz 4)
    object_dof: int
    link_pos: slice
    link_quat: slice
    link_vel: slice
    contact_names: list[str]
    contact: slice                 # C x 4 values: found, force xyz

    @property
    def num_links(self) -> int:
        return len(self.link_names)


def _hand_bodies(spec: mujoco.MjSpec, prefix: str) -> dict[str, str]:
    """Top body of each finger chain and the palm for a hand prefix ('L_' / 'R_')."""
    names = [b.name for b in spec.bodies]
    out = {"hand": next(n for n in names if n.startswith(prefix) and "hand_base" in n)}
    for finger in FINGERS:
        chain = [n for n in names if n.startswith(f"{prefix}{finger}_")]
        out[finger] = chain[0]  # bodies are listed parent-first
    return out


def add_object(spec: mujoco.MjSpec, vertices: np.ndarray, faces: np.ndarray, *, density: float, friction: float,
               contype: int, conaffinity: int, mass: float | None = None, torsional_friction: float = 0.0,
               pieces: list[np.ndarray] | None = None) -> None:
    """The object with a free joint, colliding as one convex hull of its mesh or, given `pieces` (vertices of
    convex parts, e.g. ObjectAsset.convex_parts()), as their union (InterMimic: density 200, friction 0.9).

    The mass and inertia are the solid hull's at `density` either way, so the choice of collision shape does not
    change the object's weight. `mass`, when known, overrides the density (the hull is solid; a real box is hollow
    and much lighter). `torsional_friction` (m) > 0 gives its contacts torsional friction (condim 4): a palm's contact
    patch resists the object turning about the palm's normal, which MuJoCo's point contacts (condim 3) do not."""
    hull = trimesh.Trimesh(vertices=vertices, faces=faces, process=True).convex_hull
    if mass is not None:
        density = mass / hull.volume
    # Explicit mass properties of the hull at `density`: the robot's spec does not infer inertia from geoms.
    hull.density = density
    inertia = hull.moment_inertia
    body = spec.worldbody.add_body(name=OBJECT_BODY, pos=[2.0, 0.0, 0.5])
    body.explicitinertial = True
    body.mass = float(hull.mass)
    body.ipos = np.asarray(hull.center_mass, dtype=np.float64)
    body.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    body.add_freejoint(name=OBJECT_JOINT)
    if pieces is None or len(pieces) == 1:  # one piece: the object's own hull (a convex object, or "hull")
        shapes = [(np.asarray(hull.vertices), np.asarray(hull.faces))]
    else:  # MuJoCo takes the convex hull of a mesh given by its vertices alone
        shapes = [(np.asarray(p, dtype=np.float64), None) for p in pieces]
    for i, (shape, shape_faces) in enumerate(shapes):
        name = "object_hull" if len(shapes) == 1 else f"object_piece_{i}"
        mesh = spec.add_mesh(name=name)
        mesh.uservert = shape.astype(np.float32).ravel()
        if shape_faces is not None:
            mesh.userface = shape_faces.astype(np.int32).ravel()
        # priority 1: MuJoCo takes the larger friction of two equal-priority geoms, and the floor and the robot
        # have 1.0, so `friction` (supp. Table A's 0.9 for object and ground) would act only above 1.0
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, density=density,
                      friction=[friction, torsional_friction or 0.005, 0.0001],
                      condim=4 if torsional_friction > 0 else 3, priority=1,
                      contype=contype, conaffinity=conaffinity, rgba=[0.8, 0.55, 0.3, 1.0])


def add_task_object(spec: mujoco.MjSpec, embodiment, object_asset, *, density: float, friction: float,
                    torsional_friction: float, object_collision: str) -> list[str]:
    """The interaction task's object (`add_object` on the world's collision bits, the asset's known mass winning
    over `density`) and the sensors (`add_sensors`): what training and sim2sim add alike to a robot spec. Returns
    the contact sensor names."""
    contype, conaffinity = world_bits()
    add_object(spec, np.asarray(object_asset.vertices), np.asarray(object_asset.faces), density=density,
               friction=friction, contype=contype, conaffinity=conaffinity,
               mass=getattr(object_asset, "mass_kg", None), torsional_friction=torsional_friction,
               pieces=object_asset.collision_pieces(object_collision))
    return add_sensors(spec, dict(embodiment.link_map))


def add_sensors(spec: mujoco.MjSpec, link_map: dict[str, str]) -> list[str]:
    """Link pose/velocity blocks and contact sensors; returns the contact sensor names in order."""
    body_names = {b.name for b in spec.bodies}
    site_names = {s.name for s in spec.sites}

    def frame(link: str):
        if link in site_names:
            return mujoco.mjtObj.mjOBJ_SITE
        if link in body_names:
            return mujoco.mjtObj.mjOBJ_XBODY
        raise KeyError(f"link_map entry {link!r} is neither a body nor a site of the robot")

    for kind in (mujoco.mjtSensor.mjSENS_FRAMEPOS, mujoco.mjtSensor.mjSENS_FRAMEQUAT,
                 mujoco.mjtSensor.mjSENS_FRAMELINVEL):
        for link in link_map:
            spec.add_sensor(type=kind, objtype=frame(link), objname=link)

    contacts: list[tuple[str, str, str]] = []  # (name, subtree, other body)
    for side, prefix in (("left", "L_"), ("right", "R_")):
        hand = _hand_bodies(spec, prefix)
        contacts.append((f"{side}_hand", hand["hand"], OBJECT_BODY))
        contacts += [(f"{prefix}{finger}", hand[finger], "") for finger in FINGERS]
    for name, subtree, other in (("torso", "torso_link", OBJECT_BODY),
                                 ("left_elbow", "left_elbow_link", OBJECT_BODY),
                                 ("right_elbow", "right_elbow_link", OBJECT_BODY),
                                 ("left_foot", "left_ankle_roll_link", "world"),
                                 ("right_foot", "right_ankle_roll_link", "world")):
        contacts.append((name, subtree, other))
    for name, subtree, other in contacts:
        sensor = spec.add_sensor(name=f"contact_{name}", type=mujoco.mjtSensor.mjSENS_CONTACT)
        sensor.objtype = mujoco.mjtObj.mjOBJ_XBODY  # subtree1 is given as a body with subtree semantics
        sensor.objname = subtree
        if other:
            sensor.reftype = mujoco.mjtObj.mjOBJ_BODY
            sensor.refname = other
        # data = found (bit 0) + force (bit 1); reduce = netforce (3); one slot
        sensor.intprm[0] = (1 << 0) | (1 << 1)
        sensor.intprm[1] = 3
        sensor.intprm[2] = 1
    return [c[0] for c in contacts]

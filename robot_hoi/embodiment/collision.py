"""Contact bit scheme shared by the robot, the floor and the objects the sim adds.

MuJoCo lets geoms A and B collide when (A.contype & B.conaffinity) or (B.contype & A.conaffinity) is non-zero.

    robot geom:          contype = ROBOT, conaffinity = WORLD            (self-collision off)
                         contype = ROBOT, conaffinity = WORLD | ROBOT    (self-collision on)
    floor / object geom: contype = WORLD, conaffinity = WORLD | ROBOT

So robot-floor, robot-object, object-floor and object-object contacts are always on, and robot-robot contacts
exist only with self-collision on. Visual-only geoms use contype = conaffinity = 0. Anyone adding a floor or an
object geom to the robot's MjSpec calls `set_world_collision(geom)`.
"""

from __future__ import annotations

ROBOT_COLLISION_BITS = 0b01
WORLD_COLLISION_BITS = 0b10

# Geom groups (MuJoCo viewer toggles them with the 0-5 keys).
COLLISION_GROUP = 0  # primitives that collide, visible by default
VISUAL_MESH_GROUP = 2  # optional Unitree meshes, never collide
SITE_GROUP = 4


def robot_bits(self_collision: bool) -> tuple[int, int]:
    """(contype, conaffinity) for a robot collision geom."""
    affinity = WORLD_COLLISION_BITS | (ROBOT_COLLISION_BITS if self_collision else 0)
    return ROBOT_COLLISION_BITS, affinity


def world_bits() -> tuple[int, int]:
    """(contype, conaffinity) for a floor or object geom: touches the robot and other world geoms."""
    return WORLD_COLLISION_BITS, WORLD_COLLISION_BITS | ROBOT_COLLISION_BITS


def set_world_collision(geom) -> None:
    """Give an MjSpec geom (mujoco.MjsGeom) the floor/object bits."""
    geom.contype, geom.conaffinity = world_bits()

"""The robot: physical description (g1_spec), control config (config), MuJoCo/URDF generators, link lookup.

Public entry points:
    load_embodiment(name_or_path) -> EmbodimentConfig
    build_robot_spec(cfg, *, self_collision=None, floor=True) -> mujoco.MjSpec
    build_model(cfg, **kw) -> mujoco.MjModel
    write_mjcf(cfg, path), write_urdf(cfg, path)
    resolve_link_map(model, cfg) -> {link name: LinkRef(kind 'body'|'site', id)}

mujoco is imported lazily so `load_embodiment` stays light.
"""

from __future__ import annotations

import importlib

from robot_hoi.embodiment.collision import ROBOT_COLLISION_BITS, WORLD_COLLISION_BITS, set_world_collision
from robot_hoi.embodiment.config import (
    ActuatorCfg,
    EmbodimentConfig,
    HandChannelCfg,
    load_embodiment,
)

__all__ = [
    "ROBOT_COLLISION_BITS",
    "WORLD_COLLISION_BITS",
    "ActuatorCfg",
    "EmbodimentConfig",
    "HandChannelCfg",
    "build_model",
    "build_robot_spec",
    "load_embodiment",
    "resolve_link_map",
    "body_names",
    "set_world_collision",
    "write_mjcf",
    "write_urdf",
]

_LAZY = {
    "build_model": "robot_hoi.embodiment.mjcf",
    "build_robot_spec": "robot_hoi.embodiment.mjcf",
    "write_mjcf": "robot_hoi.embodiment.mjcf",
    "write_urdf": "robot_hoi.embodiment.urdf",
    "resolve_link_map": "robot_hoi.embodiment.links",
    "body_names": "robot_hoi.embodiment.links",
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'robot_hoi.embodiment' has no attribute {name!r}")

"""Variants of a compiled MuJoCo model (numpy + mujoco only: the training backends and sim2sim's workers share it)."""

from __future__ import annotations

import copy

import mujoco
import numpy as np


def with_body_mass(model: mujoco.MjModel, body_id: int, mass: float) -> mujoco.MjModel:
    """A copy of `model` whose body `body_id` weighs `mass` kg, its inertia scaled with it (same shape and density
    distribution), and the constants derived from masses (subtree masses, inverse weights) recomputed."""
    if not mass > 0:
        raise ValueError(f"body mass must be positive, not {mass}")
    variant = copy.copy(model)
    scale = mass / float(model.body_mass[body_id])
    variant.body_mass[body_id] = mass
    variant.body_inertia[body_id] *= scale
    mujoco.mj_setConst(variant, mujoco.MjData(variant))
    return variant


def feet_centre_offset(model: mujoco.MjModel, qpos: np.ndarray, foot_bodies, root_body: str = "pelvis") -> np.ndarray:
    """(2,) mean xy of the `foot_bodies` (names) relative to `root_body`'s, at `qpos` (an upright pose at zero yaw:
    the offset in the root's heading frame)."""
    data = mujoco.MjData(model)
    data.qpos[: len(qpos)] = qpos
    mujoco.mj_kinematics(model, data)
    names = [*foot_bodies, root_body]
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) for name in names]
    if min(ids) < 0:
        raise ValueError(f"the model has no body named {[n for n, i in zip(names, ids, strict=True) if i < 0]}")
    return data.xpos[ids[:-1], :2].mean(0) - data.xpos[ids[-1], :2]

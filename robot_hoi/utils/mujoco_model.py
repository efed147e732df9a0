"""Variants of a compiled MuJoCo model (numpy + mujoco only: the training backends and sim2sim's workers share it)."""

from __future__ import annotations

import copy

import mujoco


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

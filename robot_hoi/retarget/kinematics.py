"""Named points on a MuJoCo model (bodies or sites, optionally offset), world poses and position Jacobians.

The IK, the report and the motion file see a robot "link" as one point: a body's frame origin, a site, or a fixed
offset in one of those frames (a landmark). Names are resolved to ids once; later calls are array lookups.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from robot_hoi.errors import UserError


@dataclass(frozen=True)
class LinkPoints:
    """Resolved points: point i is `offsets[i]` in the frame of site `site_ids[i]` when >= 0, else of body
    `body_ids[i]` (for a site, `body_ids[i]` is the body that carries it)."""

    names: tuple[str, ...]
    body_ids: np.ndarray  # (L,) body that carries the point
    site_ids: np.ndarray  # (L,) site id, or -1 for a body frame
    offsets: np.ndarray  # (L, 3) point in the frame's coordinates (zeros: the frame origin)

    def __len__(self) -> int:
        return len(self.names)


def resolve_links(
    model: mujoco.MjModel,
    names: list[str] | tuple[str, ...],
    frames: list[str] | tuple[str, ...] | None = None,
    offsets: np.ndarray | None = None,
) -> LinkPoints:
    """Resolve points by name. `frames[i]` (default: `names[i]`) is looked up as a site first, then as a body;
    `offsets` (L, 3) places each point in its frame. Unknown frames raise UserError listing them all."""
    frames = tuple(names) if frames is None else tuple(frames)
    body_ids, site_ids, missing = [], [], []
    for frame in frames:
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, frame)
        if site >= 0:
            site_ids.append(site)
            body_ids.append(int(model.site_bodyid[site]))
            continue
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, frame)
        if body < 0:
            missing.append(frame)
        site_ids.append(-1)
        body_ids.append(body)
    if missing:
        raise UserError(f"link names not found as a site or body in the robot model: {', '.join(missing)}")
    offsets = np.zeros((len(frames), 3)) if offsets is None else np.asarray(offsets, dtype=np.float64)
    if offsets.shape != (len(frames), 3):
        raise ValueError(f"offsets shape {offsets.shape} does not match {len(frames)} points")
    return LinkPoints(
        tuple(names), np.asarray(body_ids, dtype=np.int64), np.asarray(site_ids, dtype=np.int64), offsets)


def link_positions(data: mujoco.MjData, links: LinkPoints) -> np.ndarray:
    """(L, 3) world positions; needs mj_kinematics to have run on `data`."""
    is_site = links.site_ids >= 0
    origin = data.xpos[links.body_ids].copy()
    mats = data.xmat[links.body_ids].reshape(-1, 3, 3).copy()
    origin[is_site] = data.site_xpos[links.site_ids[is_site]]
    mats[is_site] = data.site_xmat[links.site_ids[is_site]].reshape(-1, 3, 3)
    return origin + np.einsum("lij,lj->li", mats, links.offsets)


def link_quats_wxyz(data: mujoco.MjData, links: LinkPoints) -> np.ndarray:
    """(L, 4) world orientations of the points' frames, scalar-first (MuJoCo's convention)."""
    quat = data.xquat[links.body_ids].copy()
    for i in np.flatnonzero(links.site_ids >= 0):
        mujoco.mju_mat2Quat(quat[i], data.site_xmat[links.site_ids[i]])
    return quat


def point_jacobians(
    model: mujoco.MjModel, data: mujoco.MjData, body_ids: np.ndarray, points: np.ndarray, out: np.ndarray
) -> np.ndarray:
    """Fill out (N, 3, nv) with the translational Jacobians of world points attached to bodies.

    Needs mj_kinematics and mj_comPos (mj_jac reads cdof and subtree_com).
    """
    for i, (body, point) in enumerate(zip(body_ids, points, strict=True)):
        mujoco.mj_jac(model, data, out[i], None, point, int(body))
    return out


def forward(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """The minimum for positions and Jacobians: no collision, no dynamics."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)


def joint_ids(model: mujoco.MjModel, names: list[str] | tuple[str, ...]) -> np.ndarray:
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) for name in names]
    missing = [name for name, j in zip(names, ids, strict=True) if j < 0]
    if missing:
        raise UserError(f"joint names not found in the robot model: {', '.join(missing)}")
    return np.asarray(ids, dtype=np.int64)


def free_joint_id(model: mujoco.MjModel) -> int | None:
    """The floating-base joint, or None for a fixed-base model. Only one free joint is supported."""
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    if len(free) > 1:
        raise UserError(f"robot model has {len(free)} free joints; retargeting supports one floating base")
    return int(free[0]) if len(free) else None


def apply_joint_couplings(model: mujoco.MjModel, qpos: np.ndarray) -> None:
    """Set every joint tied by an active joint equality (e.g. Inspire finger mimics) from its driver, in place.

    MuJoCo's joint equality: q1 - q1_ref = c0 + c1 d + c2 d^2 + c3 d^3 + c4 d^4, d = q2 - q2_ref (refs = qpos0).
    """
    for e in range(model.neq):
        if model.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or not model.eq_active0[e]:
            continue
        j1, j2 = int(model.eq_obj1id[e]), int(model.eq_obj2id[e])
        a1 = model.jnt_qposadr[j1]
        coef = model.eq_data[e, :5]
        if j2 < 0:
            qpos[a1] = model.qpos0[a1] + coef[0]
            continue
        a2 = model.jnt_qposadr[j2]
        d = qpos[a2] - model.qpos0[a2]
        qpos[a1] = model.qpos0[a1] + coef[0] + d * (coef[1] + d * (coef[2] + d * (coef[3] + d * coef[4])))


def default_qpos(model: mujoco.MjModel, cfg) -> np.ndarray:
    """The config's default stand: pelvis at spawn_height, upright, actuated joints at their defaults."""
    q = model.qpos0.copy()
    free = free_joint_id(model)
    if free is not None:
        adr = model.jnt_qposadr[free]
        q[adr:adr + 7] = [0.0, 0.0, cfg.spawn_height, 1.0, 0.0, 0.0, 0.0]
    adrs = model.jnt_qposadr[joint_ids(model, cfg.actuator_names)]
    q[adrs] = cfg.default_pos
    apply_joint_couplings(model, q)
    return q

"""Can the robot execute a retargeted motion? Kinematic checks of a RobotMotion on the embodiment's model.

- foot slide: horizontal travel of each foot's sole over the frames its target is planted (the human's foot is
  down and still: retarget.targets.planted) and the sole is within `contact_height` of the floor (a planted foot
  should not move; a tracking policy cannot follow a sliding one without slipping). Lift-off and touch-down frames
  of a step are not slides;
- centre of mass outside support: share of frames whose whole-body CoM (projected on the floor) lies outside
  the convex hull of the sole points touching the floor, by more than `com_margin`;
- peak and p99 joint speed of the actuated body joints (what reference-state starts copy as velocities);
- self-penetration: the deepest overlap of two robot bodies (hands in thighs, arms in the torso) and the share of
  frames with one deeper than 1 cm, on the model with self-collision on. Teachers train with self-collision off
  (InterMimic supp. F), so such a reference trains; the real robot (and sim2sim) cannot follow it there.

The dynamic hold test (does the grasp keep the object in a root-held replay) needs the training scene and lives in
robot_hoi.tasks.interaction.feasibility. All lengths in the returned dict are in cm, speeds in rad/s.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from robot_hoi.retarget.ik import sole_points
from robot_hoi.retarget.targets import TargetMapping, planted


def foot_sole_world(model: mujoco.MjModel, qpos: np.ndarray, foot_bodies: list[str]) -> dict[str, np.ndarray]:
    """{foot body: (T, P, 3) world positions of its sole points} over a qpos track (T, nq)."""
    data = mujoco.MjData(model)
    out = {}
    for name in foot_bodies:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        _, local = sole_points(model, qpos[0], [body])
        track = np.empty((len(qpos), len(local), 3))
        for t, q in enumerate(qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            track[t] = data.xpos[body] + local @ data.xmat[body].reshape(3, 3).T
        out[name] = track
    return out


def foot_slide(soles: np.ndarray, contact_height: float = 0.01, planted: np.ndarray | None = None) -> float:
    """Horizontal travel (m) of a foot's sole centre summed over consecutive frames that both touch the floor (and,
    with `planted` (T,) given, where the reference plants the foot in both)."""
    low = soles[..., 2].min(-1) < contact_height
    if planted is not None:
        low = low & planted
    centre = soles[..., :2].mean(-2)
    both = low[1:] & low[:-1]
    return float(np.linalg.norm(np.diff(centre, axis=0), axis=-1)[both].sum())


def com_track(model: mujoco.MjModel, qpos: np.ndarray, root_body: int = 1) -> np.ndarray:
    """(T, 3) centre of mass of the subtree rooted at `root_body` (the robot) per frame."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), 3))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        out[t] = data.subtree_com[root_body]
    return out


def support_distance(com_xy: np.ndarray, contact_points_xy: np.ndarray) -> float:
    """Signed distance (m) of a point outside (> 0) or inside (< 0) the convex hull of the contact points."""
    if len(contact_points_xy) < 3:
        return np.inf
    try:
        hull = ConvexHull(contact_points_xy)
    except QhullError:
        return np.inf
    # hull.equations: n . x + b <= 0 inside; the max over faces is the signed distance for a convex polygon
    return float((hull.equations[:, :2] @ com_xy + hull.equations[:, 2]).max())


def self_penetration(model: mujoco.MjModel, qpos: np.ndarray, tolerance: float = 0.01, top: int = 3) -> dict:
    """Robot-robot overlaps along a qpos track, on `model` compiled with self-collision on: the deepest (cm), the
    share of frames with one deeper than `tolerance` (m), and the `top` body pairs by depth."""
    data = mujoco.MjData(model)
    pairs: dict[str, float] = {}
    frames = 0
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_fwdPosition(model, data)
        deepest = 0.0
        for contact in data.contact[: data.ncon]:
            b1, b2 = model.geom_bodyid[contact.geom1], model.geom_bodyid[contact.geom2]
            if b1 == 0 or b2 == 0:  # the world (floor): not a self-contact
                continue
            depth = max(-float(contact.dist), 0.0)
            key = " / ".join(sorted((model.body(b1).name, model.body(b2).name)))
            pairs[key] = max(pairs.get(key, 0.0), depth)
            deepest = max(deepest, depth)
        frames += deepest > tolerance
    worst = sorted(pairs.items(), key=lambda kv: -kv[1])[:top]
    return {
        "self_penetration_cm": round(100 * max(pairs.values(), default=0.0), 2),
        "self_penetration_fraction": round(frames / max(len(qpos), 1), 3),
        "self_penetration_pairs": {k: round(100 * v, 2) for k, v in worst if v > tolerance},
    }


def kinematic_feasibility(model: mujoco.MjModel, motion, foot_bodies: list[str], body_joint_ids: list[int],
                          contact_height: float = 0.01, com_margin: float = 0.0,
                          self_collision_model: mujoco.MjModel | None = None) -> dict:
    """Foot slide, CoM-outside-support share, joint speeds and (given `self_collision_model`) self-penetration of a
    RobotMotion (see the module docstring)."""
    soles = foot_sole_world(model, motion.qpos, foot_bodies)
    names = list(motion.link_names)
    rule = TargetMapping()
    down = {name: planted(motion.target_pos[:, [names.index(name)]], motion.fps, rule.pin_height,
                          rule.pin_speed)[:, 0] if name in names else None for name in foot_bodies}
    slide = {name: round(100 * foot_slide(track, contact_height, down[name]), 2) for name, track in soles.items()}
    com = com_track(model, motion.qpos)
    points = np.concatenate(list(soles.values()), axis=1)  # (T, P, 3)
    outside = []
    for t in range(len(com)):
        touching = points[t][points[t, :, 2] < contact_height, :2]
        outside.append(support_distance(com[t, :2], touching) > com_margin)
    speed = np.abs(np.diff(motion.joint_pos[:, body_joint_ids], axis=0)) * motion.fps
    report = {
        "foot_slide_cm": slide,
        "com_outside_support_fraction": round(float(np.mean(outside)), 3),
        "joint_speed_peak_rad_s": round(float(speed.max()) if speed.size else 0.0, 2),
        "joint_speed_p99_rad_s": round(float(np.percentile(speed, 99)) if speed.size else 0.0, 2),
    }
    if self_collision_model is not None:
        report.update(self_penetration(self_collision_model, motion.qpos))
    return report

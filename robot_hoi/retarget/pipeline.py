"""Clip -> RobotMotion: targets (targets.py), finger poses (hands.py), IK (ik.py), then the report (report.py)."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from robot_hoi.data.contacts import hand_contact_need
from robot_hoi.embodiment import build_model
from robot_hoi.retarget.executable import (
    ExecutableSettings,
    limit_speed,
    load_offsets,
    smooth_joints,
    squeeze_offsets,
)
from robot_hoi.retarget.faces import centre_of_mass, hull_mass
from robot_hoi.retarget.grasp import GraspPlan, GraspSettings, apply_plan, plan_grasps
from robot_hoi.retarget.hand_geometry import hand_geometry
from robot_hoi.retarget.hands import GraspRule, HandJoints, closure_profile, finger_angles, holding
from robot_hoi.retarget.ik import IKResult, IKSettings, IKSolver
from robot_hoi.retarget.kinematics import (
    default_qpos,
    joint_ids,
    link_positions,
    resolve_links,
)
from robot_hoi.retarget.landmarks import landmarks_for
from robot_hoi.retarget.motion import RobotMotion, finite_difference_qvel
from robot_hoi.retarget.object_contact import hand_probe_points, subtree
from robot_hoi.retarget.qp import QPRetargeter, QPSettings
from robot_hoi.retarget.targets import (
    RobotTargets,
    TargetMapping,
    hand_side,
    link_group,
    planted,
    targets_from_clip,
)


@dataclass(frozen=True)
class RetargetOptions:
    mapping: TargetMapping = field(default_factory=TargetMapping)
    ik: IKSettings = field(default_factory=IKSettings)  # ik.solver: "dls" | "qp"
    qp: QPSettings = field(default_factory=QPSettings)  # the QP retarget's settings (ik.solver "qp")
    grasp: GraspRule = field(default_factory=GraspRule)
    grasp_plan: GraspSettings = field(default_factory=GraspSettings)  # robot grasps in held segments (grasp.py)
    use_landmarks: bool = True  # IK on anatomical landmarks (landmarks.py) instead of the raw link origins
    executable: ExecutableSettings = field(default_factory=ExecutableSettings)  # smoothing + grasp squeeze
    # The IK keeps the arm out of the object from this many bodies above the wrist-yaw link down to the fingertips
    # (G1: 4 = from the upper arm). With the hands alone, sub3_largebox_003's left elbow sat 3 cm inside the box: in
    # the root-held replay the elbow pushed the box 4.6 cm away and the left hand never reached its grip
    # (contact_lost 20 frames in); with the arms (and leg loads), both hands hold until the lift (object_deviation after 29 frames)
    arm_probe_levels: int = 4


@dataclass
class RetargetResult:
    motion: RobotMotion
    targets: RobotTargets
    ik: IKResult
    hold: dict[str, np.ndarray]  # side -> (T,) bool, the hand holds the object
    seconds: float  # IK wall time

LIFTED_M = 0.02  # object this far above its lowest height counts as carried (its weight on the hands)
DYNAMICS_SIGMA_S = 0.05  # s, Gaussian low-pass of the reference velocity and acceleration for compensate_dynamics


def hand_joints(cfg) -> list[HandJoints]:
    """Per hand: its channel joints, open = the actuator default, closed = the channel's closed angle."""
    default = dict(zip(cfg.actuator_names, cfg.default_pos, strict=True))
    return [
        HandJoints(
            side=side,
            joint_names=tuple(c.joint for c in hand.channels),
            open_rad=tuple(float(default[c.joint]) for c in hand.channels),
            closed_rad=tuple(float(c.closed_rad) for c in hand.channels),
        )
        for side, hand in cfg.hands.items()
    ]


def finger_presets(
    model: mujoco.MjModel, cfg, targets: RobotTargets, base_qpos: np.ndarray, rule: GraspRule
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(T, nq) qpos carrying the finger angles per frame (other entries = base_qpos), and the hold flags."""
    preset = np.tile(base_qpos, (targets.num_frames, 1))
    hold = {}
    for hand in hand_joints(cfg):
        tips = [i for i, h in enumerate(targets.human_names)
                if link_group(h) == "fingers" and hand_side(h) == hand.side]
        hold[hand.side] = holding(targets.anchor, tips, rule.threshold)
        angles = finger_angles(hand, closure_profile(hold[hand.side], targets.fps, rule))
        preset[:, model.jnt_qposadr[joint_ids(model, hand.joint_names)]] = angles
    return preset, hold


def retarget_targets(
    model: mujoco.MjModel, cfg, targets: RobotTargets, options: RetargetOptions | None = None,
    plan: GraspPlan | None = None,
) -> RetargetResult:
    """Solve the IK for prepared targets and package the motion; `plan`: the grips the targets were moved to
    (grasp.apply_plan), whose finger postures, squeeze and finger press then replace the closure rule's."""
    options = options or RetargetOptions()
    q_default = default_qpos(model, cfg)
    finger_joint_names = {j for hand in hand_joints(cfg) for j in hand.joint_names}
    body_joints = [n for n in cfg.actuator_names if n not in finger_joint_names]
    feet = [r for r, h in zip(targets.link_names, targets.human_names, strict=True) if link_group(h) == "feet"]
    landmarks = landmarks_for(cfg.name, targets.link_names) if options.use_landmarks else {}
    wrists = [r for r, h in zip(targets.link_names, targets.human_names, strict=True) if link_group(h) == "wrists"]
    probes = None
    if wrists:
        wrist_ids = resolve_links(model, wrists).body_ids
        probes = hand_probe_points(model, wrist_ids, _ancestors(model, wrist_ids, options.arm_probe_levels))
    solver = IKSolver(model, targets.link_names, body_joints, q_default, feet, options.ik, landmarks, probes)
    preset, hold = finger_presets(model, cfg, targets, q_default, options.grasp)
    if plan is not None:
        hold = _apply_plan_fingers(model, cfg, plan, preset, hold)

    start = time.perf_counter()
    track = None
    if targets.object_hull is not None:
        track = (targets.object_hull, targets.object_pos, targets.object_quat_wxyz)
    upper = [n for n in body_joints if not any(k in n for k in ("hip", "knee", "ankle"))]
    qp_fallbacks = None
    if options.ik.solver == "qp":  # hard limits and contacts inside the solve: nothing to repair afterwards
        qp = QPRetargeter(solver, options.qp)
        result = qp.solve(targets.pos, targets.weight, targets.fps, preset, targets.root_quat_wxyz, track,
                          targets.object_points_local, _stance(solver, targets, feet, options.mapping))
        qp_fallbacks = qp.fallbacks
    else:
        result = solver.solve(targets.pos, targets.weight, preset, targets.root_quat_wxyz, object_track=track)
        # legs stay as solved: smoothing them alone would move planted feet (the root keeps its path)
        upper_qadr = model.jnt_qposadr[joint_ids(model, upper)]
        smoothed = smooth_joints(result.qpos, upper_qadr, targets.fps, options.executable)
        result = _depenetrate(solver, solver.evaluate(smoothed, targets.pos, result.iterations, track), targets,
                              track)
        limited = result.qpos.copy()  # the push-out may step fast again: the speed limit has the last word
        limited[:, upper_qadr] = limit_speed(limited[:, upper_qadr], options.executable.max_joint_speed / targets.fps)
        result = solver.evaluate(limited, targets.pos, result.iterations, track)
    squeeze = _squeeze(model, cfg, result.qpos, hold, targets.fps, options, solver, track, plan)
    legs = options.executable.compensate_leg_loads
    soles = (solver.sole_body, solver.sole_local) if legs and len(solver.sole_body) else None
    loads = _load_compensation(model, result.qpos, body_joints if legs else upper, hold, targets, options, soles)
    seconds = time.perf_counter() - start

    act_qadr = model.jnt_qposadr[model.actuator_trnid[:, 0]]
    actuator_names = tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(model.nu))
    motion = RobotMotion(
        fps=targets.fps,
        qpos=result.qpos,
        qvel=finite_difference_qvel(model, result.qpos, targets.fps),
        joint_pos=(result.qpos + squeeze + loads)[:, act_qadr],  # PD targets: state + grasp squeeze + loads
        link_pos=result.link_pos,
        link_quat_wxyz=result.link_quat_wxyz,
        target_pos=targets.pos,
        object_pos=targets.object_pos,
        object_quat_wxyz=targets.object_quat_wxyz,
        anchor=targets.anchor,
        residual=result.residual,
        link_names=targets.link_names,
        human_names=targets.human_names,
        actuator_names=actuator_names,
        embodiment=cfg.name,
        scale=targets.scale,
        meta={
            "mapping": asdict(options.mapping),
            "ik": asdict(options.ik),
            **({"qp": asdict(options.qp), "qp_fallbacks": qp_fallbacks} if qp_fallbacks is not None else {}),
            "grasp": asdict(options.grasp),
            "grasp_plan": asdict(options.grasp_plan),
            "executable": asdict(options.executable),
            "landmarks": {k: [f, list(off)] for k, (f, off) in landmarks.items()},
        },
    )
    return RetargetResult(motion=motion, targets=targets, ik=result, hold=hold, seconds=seconds)


def _stance(solver: IKSolver, targets: RobotTargets, feet: list[str], mapping: TargetMapping) -> dict[int, np.ndarray]:
    """{foot body: (T,) bool} frames where every foot target on that body is planted (targets.planted)."""
    names = list(targets.link_names)
    out: dict[int, np.ndarray] = {}
    for name in feet:
        i = names.index(name)
        down = planted(targets.pos[:, [i]], targets.fps, mapping.pin_height, mapping.pin_speed)[:, 0]
        body = int(solver.points.body_ids[i])
        out[body] = out[body] & down if body in out else down
    return out


def _ancestors(model: mujoco.MjModel, bodies: np.ndarray, levels: int) -> np.ndarray:
    """Each body's ancestor `levels` up (stopping below the world body)."""
    out = np.asarray(bodies, dtype=np.int64).copy()
    for _ in range(levels):
        parent = model.body_parentid[out]
        out = np.where(parent > 0, parent, out)
    return out


def _depenetrate(solver: IKSolver, result: IKResult, targets: RobotTargets, track, depth: float = 0.01,
                 iterations: int = 4, passes: int = 3) -> IKResult:
    """Smoothing can drag a hand into the object where the IK had jumped around it: a few IK iterations (with the
    hull's push-out rows), warm-started from the smoothed pose, on the frames where a probe is deeper than
    `depth`."""
    for _ in range(passes):
        frames = np.flatnonzero(result.object_penetration > depth)
        if track is None or not len(frames):
            break
        qpos = solver.refine_frames(result.qpos, targets.pos, targets.weight, frames, iterations, track)
        result = solver.evaluate(qpos, targets.pos, result.iterations, track)
    return result


def _squeeze(model: mujoco.MjModel, cfg, qpos: np.ndarray, hold: dict[str, np.ndarray], fps: float,
             options: RetargetOptions, solver: IKSolver, track, plan: GraspPlan | None = None) -> np.ndarray:
    """(T, nq) grasp-squeeze offsets for the PD targets (executable.py), ramped like the finger closure (at the
    same rate; flat fingers, closure 0, still squeeze). Into the surface needs the object `track` (None: no
    object) and the solver's hand probes. Where a `plan` grips, its hands squeeze along its directions instead
    (ramped by its squeeze weight) and its fingers close its `press` further."""
    settings = options.executable
    into_surface = settings.squeeze_toward == "surface"
    sides = ("left", "right")
    out = np.zeros_like(qpos)
    if settings.squeeze_depth <= 0 or set(hold) != set(sides) or (into_surface and track is None):
        return out
    wrists = {side: f"{side}_wrist_yaw_link" for side in sides}
    arms = {side: [f"{side}_shoulder_pitch_joint", f"{side}_shoulder_roll_joint", f"{side}_shoulder_yaw_joint",
                   f"{side}_elbow_joint"] for side in sides}
    full_stroke = replace(options.grasp, closure=1.0)
    ramp = {side: closure_profile(hold[side], fps, full_stroke) for side in sides}
    if plan is not None:
        ramp = {side: np.where(plan.blend[side] > 0, 0.0, ramp[side]) for side in sides}
        out += squeeze_offsets(model, qpos, plan.squeeze, wrists, arms, settings, plan.into)
        for hand in hand_joints(cfg):
            adr = model.jnt_qposadr[joint_ids(model, hand.joint_names)]
            out[:, adr] += plan.squeeze[hand.side][:, None] * plan.press[hand.side]
    if not any(r.any() for r in ramp.values()):
        return out
    directions = _into_surface(solver, qpos, track, wrists, ramp) if into_surface else None
    return out + squeeze_offsets(model, qpos, ramp, wrists, arms, settings, directions)


def _apply_plan_fingers(model: mujoco.MjModel, cfg, plan: GraspPlan, preset: np.ndarray,
                        hold: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """In place: the finger channels of `preset` blended to the plan's grip postures; returns the hold flags
    (the plan's where it grips, the closure rule's elsewhere)."""
    out = dict(hold)
    for hand in hand_joints(cfg):
        w = plan.blend[hand.side][:, None]
        adr = model.jnt_qposadr[joint_ids(model, hand.joint_names)]
        preset[:, adr] = (1.0 - w) * preset[:, adr] + w * plan.channel_angles[hand.side]
        out[hand.side] = np.where(plan.blend[hand.side] > 0, plan.hold(hand.side), hold[hand.side])
    return out


def _into_surface(solver: IKSolver, qpos: np.ndarray, track, wrists: dict[str, str],
                  ramp: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """{side: (T, 3)} the inward normal of the object face nearest each hand's collision spheres, where it holds."""
    model = solver.model
    sides = list(wrists)
    probe_sets = [np.flatnonzero(solver.probes.hand & np.isin(solver.probes.body_ids, subtree(
        model, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, wrists[side])))) for side in sides]
    frames = np.flatnonzero(sum(ramp.values()) > 0)
    normals = solver.nearest_face_normals(qpos, frames, track, probe_sets)
    out = {side: np.zeros((len(qpos), 3)) for side in sides}
    for k, side in enumerate(sides):
        out[side][frames] = -normals[:, k]
    return out


def _load_compensation(model: mujoco.MjModel, qpos: np.ndarray, joints: list[str], hold: dict[str, np.ndarray],
                       targets: RobotTargets, options: RetargetOptions,
                       soles: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """(T, nq) load-compensation offsets for the `joints`' PD targets (executable.py; waist and arms, and the legs
    with compensate_leg_loads): gravity on the links, and the object's weight (when its mass is known) shared by the
    holding hands while it is off its rest; with `soles` (leg loads), carried down to the feet on the floor."""
    if not options.executable.compensate_loads:
        return np.zeros_like(qpos)
    dynamic = options.executable.compensate_dynamics
    carried = {}
    if targets.object_mass_kg and set(hold) == {"left", "right"}:
        z = targets.object_pos[:, 2]
        lifted = np.clip((z - z.min()) / LIFTED_M, 0.0, 1.0)  # the floor carries the object until it rises
        both = sum(hold[side].astype(float) for side in hold)
        g = 9.81 + (np.gradient(np.gradient(z, 1.0 / targets.fps), 1.0 / targets.fps) if dynamic else 0.0)
        for side in hold:
            share = np.where(hold[side], 1.0 / np.maximum(both, 1.0), 0.0)
            carried[f"{side}_wrist_yaw_link"] = lifted * share * targets.object_mass_kg * np.maximum(g, 0.0)
    motion = None
    if dynamic:
        # the legs are not smoothed (planted feet): low-pass what is differentiated, or the PD targets jump
        sigma = DYNAMICS_SIGMA_S * targets.fps
        qvel = gaussian_filter1d(finite_difference_qvel(model, qpos, targets.fps), sigma, axis=0, mode="nearest")
        motion = (qvel, gaussian_filter1d(np.gradient(qvel, 1.0 / targets.fps, axis=0), sigma, axis=0, mode="nearest"))
    return load_offsets(model, qpos, joints, carried, soles, options.executable.support_height, motion)


def robot_hand_lengths(model: mujoco.MjModel, link_map: dict[str, str]) -> dict[str, float]:
    """{"left"/"right": mean distance from the wrist link to the mapped fingertip links} in the model's rest pose."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    lengths = {}
    for side in ("left", "right"):
        hand = [(robot, human) for robot, human in link_map.items() if hand_side(human) == side]
        wrists = [robot for robot, human in hand if link_group(human) == "wrists"]
        tips = [robot for robot, human in hand if link_group(human) == "fingers"]
        if len(wrists) == 1 and tips:
            wrist = link_positions(data, resolve_links(model, wrists))[0]
            tip_pos = link_positions(data, resolve_links(model, tips))
            lengths[side] = float(np.linalg.norm(tip_pos - wrist, axis=-1).mean())
    return lengths


def clip_grasps(model: mujoco.MjModel, cfg, clip, targets: RobotTargets, options: RetargetOptions) -> GraspPlan:
    """The grips (grasp.py) for a clip's targets: its held segments, the convex pieces the simulation collides
    with and their centre of mass."""
    pieces = clip.object.collision_pieces(options.mapping.object_collision)
    geometries = {side: hand_geometry(model, cfg, side, targets.link_names, targets.human_names)
                  for side in cfg.hands}
    return plan_grasps(targets, hand_contact_need(clip, targets.num_frames), pieces,
                       centre_of_mass(clip.object.vertices, clip.object.faces), geometries, options.grasp_plan)


def retarget_clip(
    clip,
    cfg,
    model: mujoco.MjModel | None = None,
    scale: float | None = None,
    options: RetargetOptions | None = None,
) -> RetargetResult:
    """HOIClip + embodiment config -> RetargetResult (motion, targets, IK details)."""
    options = options or RetargetOptions()
    if model is None:
        model = build_model(cfg)
    targets = targets_from_clip(clip, cfg, scale=scale, mapping=options.mapping,
                                hand_length=robot_hand_lengths(model, cfg.link_map))
    plan = None
    if options.grasp_plan.enabled:
        plan = clip_grasps(model, cfg, clip, targets, options)
        targets = apply_plan(targets, plan, options.grasp_plan.weight)
        density = options.grasp_plan.object_density
        if targets.object_mass_kg is None and density:
            targets = replace(targets, object_mass_kg=hull_mass(clip.object.vertices, clip.object.faces, density))
    out = retarget_targets(model, cfg, targets, options, plan)
    out.motion.meta["clip"] = str(getattr(clip, "name", "") or getattr(clip, "source", ""))
    return out

"""Grasps the Inspire hand can make: robot hand placements on the object during the clip's held segments.

OMOMO hands are flat and often sit inside the object; a human pinches a tabletop's edge with the fingers under
it, or pushes a box with a palm on its top. Placing the robot hand where the human's was leaves the Inspire
fingers in the air or the two hands on adjacent faces of a box. With the planner on (`GraspSettings.enabled`,
the task's `retarget.grasp`), each grip episode (a run of frames where some hand must touch the object,
data.contacts.hand_contact_need) gets contacts chosen on the sides of the convex pieces the simulation collides
with (faces.py), by what the object does while held:

* "claw" (two hands lift or hold it): the pair of roughly opposite sides with horizontal normals whose grip
  points lie nearest the human's hands. The grasp axis passes over the centre of mass, at the hands' height
  but at least `hang_m` above it (an object hanging below the axis stays upright, one balanced above it
  topples). Each hand keeps the human hand's orientation turned palm into its side, fingers curled `closure` with
  the pads on the side: the G1 wrist and forearm and the open Inspire thumb stand proud of the palm, so a flat
  palm cannot lie on a large side (hand_geometry.py).
* "push" (the object slides away from the hands, which are behind its centre of mass, and is not lifted): palms
  flat on the top, fingers ahead, the heel of the hand and the wrist catching the top's rear edge, the hands
  either side of the centre of mass; the PD targets press ahead and a little down. One hand pushes the same way.
* "hook" (the object slides toward the hands, which are on its leading side, and is not lifted: a table drag):
  on the leading side thinner than the hand (a tabletop's edge), fingers pointing down past its bottom edge and
  curled under it; the PD targets pull toward the hands and up.
* a one-hand lift keeps the human's placement (handles are not detected).

The fingers close through the hand's couplings, each finger on its own: a claw's longest finger to `closure` with
its pad on the face and every other finger until its pad is as near the face as it gets (one pad per hand on one
line through the object let the box pivot about the grasp axis, 30 degrees in `sub3_largebox_003`'s lift), a
push's or a hook's fingers each until it first touches the object (HandGeometry.finger_closures); the PD targets
close them `press` further and move the wrist into the contact (executable.squeeze_offsets), ramped in after the
held segment starts (a hand squeezed while arriving sticks where it lands) and, for two hands, only while both
hold. The wrist and fingertip targets ride with the
object's pose, so its path is unchanged; they glide from the human's over `blend_s` before a held segment (in
along the face normal from `approach_m` out) and back after it. With a known or density-based object mass the
load offsets carry its weight in the gripping hands.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.data.segments import mask_segments
from robot_hoi.retarget.faces import Face, face_distance, object_faces
from robot_hoi.retarget.hand_geometry import (
    HandGeometry,
    finger_rotation,
    fitted_rotation,
    place_hand,
    turn_palm,
)
from robot_hoi.retarget.object_contact import HullPlanes
from robot_hoi.retarget.targets import RobotTargets, to_object_frame, wxyz_to_xyzw

SIDES = ("left", "right")


@dataclass(frozen=True)
class GraspSettings:
    enabled: bool = False        # off: the hands go where the human's were (targets.py)
    # s the hand glides between the human's placement and the grasp: sub2_largetable_003 asked 1-3 m/s of the
    # wrists over 0.3 s, which the arms' PD servos trailed by 10 cm
    blend_s: float = 0.8
    approach_m: float = 0.05     # m out along the face normal where the glide in ends its approach
    # A lifted object turns about the grasp axis until its centre of mass hangs below it; only the contacts'
    # torsional friction (~0.3 N m per hand here) resists that. So a lift's axis passes at most `beside_m` beside
    # the centre of mass (sub3_largebox_003 turned 30 degrees with 3 cm) and at least `hang_m` above it (a box
    # balanced on an axis below its centre topples), where the faces reach that high.
    beside_m: float = 0.005
    hang_m: float = 0.05
    lift_m: float = 0.1          # m the object rises in an episode for it to count as lifted (a drag lifts a few cm)
    move_m: float = 0.05         # m the object slides in an episode for it to count as pushed or dragged
    edge_margin_m: float = 0.02  # m a palm centre stays inside its face's edges
    palm_gap_m: float = 0.003    # m between the face and the hand's nearest point in the reference
    closure: float = 0.5         # the claw's finger stroke fraction (its pads reach furthest toward the face)
    max_closure: float = 0.8     # a push's or hook's fingers close at most this far looking for the object
    press: float = 0.15          # stroke fraction the finger PD targets close past the grip's closure
    squeeze_s: float = 0.15      # s the squeeze and press ramp in after a held segment starts (and out before it ends)
    hook_below_m: float = 0.01   # m a hook's finger roots go below the edge they curl under
    weight: float = 3.0          # IK weight of a gripping hand's links (a wrist on the object: 1 + 2)
    # kg/m^3 of the simulated object where the clip knows no mass (the task's env.object_density): the load
    # offsets then carry the object's weight in the gripping hands, as the simulation loads them
    object_density: float | None = None


@dataclass(frozen=True)
class Grip:
    """One hand's planned contact over one grip episode, object frame."""

    side: str
    kind: str                # "claw" | "push" | "hook"
    frames: tuple[int, int]  # the episode, first and last frame
    face: Face
    point: np.ndarray        # where the hand touches the face
    rotation: np.ndarray     # (3, 3) wrist orientation
    wrist: np.ndarray        # wrist link origin
    closure: np.ndarray      # (6,) stroke fraction of each finger channel in the grip
    into: np.ndarray         # unit direction the PD targets squeeze the wrist in


@dataclass
class GraspPlan:
    """Per side: the grips and what they ask of each frame (T frames; world = the targets' robot space)."""

    grips: list[Grip]
    links: dict[str, tuple[str, ...]]        # the side's hand links (HandGeometry.links)
    blend: dict[str, np.ndarray]             # (T,) 0 (the human's placement) .. 1 (gripping)
    link_pos: dict[str, np.ndarray]          # (T, K, 3) the grip's link targets (where blend > 0)
    channel_angles: dict[str, np.ndarray]    # (T, 6) the grip's finger channels (where blend > 0)
    press: dict[str, np.ndarray]             # (T, 6) channel PD-target offsets at full squeeze
    squeeze: dict[str, np.ndarray]           # (T,) 0 .. 1: how much of the squeeze and press the PD targets carry
    into: dict[str, np.ndarray]              # (T, 3) world unit squeeze direction (0 where no grip)

    def hold(self, side: str) -> np.ndarray:
        """(T,) bool: the hand grips."""
        return self.blend[side] >= 1.0 - 1e-9


@dataclass(frozen=True)
class Episode:
    """What the planner reads of one grip episode, object frame (its pose at the episode's first frame)."""

    first: int
    last: int
    held: dict[str, np.ndarray]    # side -> (F,) bool over the episode's frames
    hands: dict[str, np.ndarray]   # side -> (K, 3) the human's hand links (targets), mean over its held frames
    arms: dict[str, np.ndarray]    # side -> (3,) the shoulder target, mean over the episode
    up: np.ndarray                 # world up
    lifted: bool
    motion: np.ndarray             # unit horizontal direction the object slides in (zeros: it does not)

    def palm(self, side: str) -> np.ndarray:
        return self.hands[side].mean(0)


def grip_episodes(need: np.ndarray) -> list[tuple[int, int, tuple[str, ...]]]:
    """(first, last, sides) of each run of frames where some hand must touch the object; `need` (T, 2)."""
    need = np.asarray(need, dtype=bool)
    return [(a, b, tuple(s for k, s in enumerate(SIDES) if need[a:b + 1, k].any()))
            for a, b in mask_segments(need.any(axis=1))]


def episode_kind(episode: Episode, com: np.ndarray) -> str | None:
    """"push", "hook" (a drag), "claw" (two hands lift or hold it) or None (one hand that neither pushes nor drags:
    the human's placement); see the module docstring."""
    if np.linalg.norm(episode.motion) > 0 and not episode.lifted:
        ahead = float((np.mean([episode.palm(s) for s in episode.held], axis=0) - com) @ episode.motion)
        return "hook" if ahead > 0 else "push"
    return "claw" if len(episode.held) == 2 else None


def opposing_faces(faces: list[Face], episode: Episode, com: np.ndarray, settings: GraspSettings,
                   max_span: float = 0.9) -> tuple[dict[str, Face], dict[str, np.ndarray]] | None:
    """({side: face}, {side: grip point}): of the pairs of faces with horizontal normals that look roughly away
    from each other and face each other across the object, the one whose grip points (opposing_points) lie
    nearest the human's hands."""
    sides = [f for f in faces if abs(f.normal @ episode.up) < 0.5]
    best, best_cost = None, np.inf
    for a in sides:
        for b in sides:
            span = -(a.normal @ b.centre + a.offset)  # b lies this far inside a's plane
            if a is b or a.normal @ b.normal > -0.8 or not 0.05 < span < max_span:
                continue
            pair = {"left": a, "right": b}
            points = opposing_points(pair, episode, com, settings)
            apart = points["left"] - points["right"]
            if np.linalg.norm(apart - (apart @ a.normal) * a.normal) > settings.edge_margin_m:
                continue  # the faces do not overlap across the object there
            cost = sum(float(np.linalg.norm(points[s] - episode.palm(s))) for s in pair)
            if cost < best_cost:
                best, best_cost = (pair, points), cost
    return best


def opposing_points(faces: dict[str, Face], episode: Episode, com: np.ndarray,
                    settings: GraspSettings) -> dict[str, np.ndarray]:
    """Grip points on two opposite faces: the grasp axis through the hands' mean, for a lift moved over the
    centre of mass (at most `beside_m` beside it and at least `hang_m` above it, within the faces' edges)."""
    normal = faces["left"].normal
    offset = np.mean([episode.palm(s) for s in SIDES], axis=0) - com
    offset -= (offset @ normal) * normal
    if episode.lifted:
        vertical = episode.up - (episode.up @ normal) * normal
        vertical /= max(np.linalg.norm(vertical), 1e-9)
        height = float(offset @ vertical)
        across = offset - height * vertical
        size = max(float(np.linalg.norm(across)), 1e-9)
        offset = max(height, settings.hang_m) * vertical + across * min(1.0, settings.beside_m / size)
    return {side: face.clamp(com + offset, settings.edge_margin_m) for side, face in faces.items()}


def side_by_side(episode: Episode, centre: np.ndarray, lateral: np.ndarray,
                 min_spacing: float = 0.12) -> dict[str, np.ndarray]:
    """Points for the episode's hands across `lateral` (unit): one hand at `centre`, two either side of it as far
    apart as the human's (at least `min_spacing`)."""
    if len(episode.held) == 1:
        return {side: centre.copy() for side in episode.held}
    across = {side: float((episode.palm(side) - centre) @ lateral) for side in SIDES}
    half = max(abs(across["left"] - across["right"]) / 2, min_spacing / 2)
    order = 1.0 if across["left"] >= across["right"] else -1.0
    return {side: centre + (order if side == "left" else -order) * half * lateral for side in SIDES}


def top_face(faces: list[Face], up: np.ndarray) -> Face | None:
    """The face that looks most nearly up (within 45 degrees), if any."""
    tops = [f for f in faces if f.normal @ up > 0.7]
    return max(tops, key=lambda f: f.normal @ up) if tops else None


def leading_face(faces: list[Face], episode: Episode, thinner_than: float) -> Face | None:
    """The face looking along the motion (within 45 degrees) and less than `thinner_than` tall, nearest the
    hands."""
    lead = [f for f in faces if f.normal @ episode.motion > 0.7
            and np.subtract(*f.extent(episode.up, f.centre)[::-1]) < thinner_than]
    return min(lead, key=lambda f: sum(face_distance(episode.palm(s), f) for s in episode.held)) if lead else None


def finger_direction(face: Face, point: np.ndarray, shoulder: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Along the face away from the shoulder (the hand extends the arm); down the face when the shoulder faces it
    square on."""
    for direction in (point - shoulder, -up):
        along = direction - (direction @ face.normal) * face.normal
        if np.linalg.norm(along) > 1e-3:
            return along / np.linalg.norm(along)
    return face.basis()[0]


def claw_pose(geometry: HandGeometry, face: Face, point: np.ndarray, rotation: np.ndarray, closure: float,
              planes: HullPlanes, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """(rotation, wrist): the hand oriented like `rotation` turned palm into the face, the fingers curled
    `closure`, their pads (the probes reaching furthest toward the palm side) centred on `point` `gap` off the
    face; moved out where another probe would sink in deeper."""
    rotation = turn_palm(geometry, rotation, -face.normal)
    probes = geometry.at(closure)[1]
    reach = probes @ geometry.palm_normal + geometry.probe_radius
    deepest = reach[geometry.finger].max()
    centre = probes[geometry.finger & (reach > deepest - 0.01)].mean(0)
    centre -= (centre @ geometry.palm_normal) * geometry.palm_normal
    wrist = point + face.normal * (deepest + gap) - rotation @ centre
    return rotation, wrist + face.normal * max(geometry.sink(rotation, wrist, planes, closure) - gap, 0.0)


def push_pose(geometry: HandGeometry, top: Face, point: np.ndarray, heading: np.ndarray, planes: HullPlanes,
              gap: float, heel: float = 0.02) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(palm centre, rotation, wrist) of a hand pushing along `heading`: palm flat on the top, fingers ahead, the
    wrist `heel` behind the top's rear edge so that the heel of the hand and the wrist catch the rear face."""
    fingers = heading - (heading @ top.normal) * top.normal
    fingers /= np.linalg.norm(fingers)
    rotation = finger_rotation(geometry, top, fingers)
    rear = top.extent(fingers, point)[0]
    centre = point + fingers * (rear + geometry.palm_centre @ geometry.axis - heel)
    centre -= (top.normal @ centre + top.offset) * top.normal
    wrist = place_hand(geometry, top, centre, rotation, gap)
    return centre, rotation, wrist + top.normal * geometry.sink(rotation, wrist, planes, 0.0)


def hook_pose(geometry: HandGeometry, face: Face, point: np.ndarray, up: np.ndarray, planes: HullPlanes,
              gap: float, below: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(palm centre, rotation, wrist) of a hand hooking under the face's bottom edge: palm toward the face,
    fingers pointing down with their roots `below` the edge (the hand's nearest point `gap` off the face)."""
    down = -(up - (up @ face.normal) * face.normal)
    down /= np.linalg.norm(down)
    rotation = finger_rotation(geometry, face, down)
    probes = geometry.at(0.0)[1]
    roots = float((probes[geometry.finger] @ geometry.axis).min() - geometry.palm_centre @ geometry.axis)
    centre = point + down * (face.extent(down, point)[1] + below - roots)
    wrist = place_hand(geometry, face, centre, rotation, geometry.reach + gap)
    return centre, rotation, wrist + face.normal * geometry.sink(rotation, wrist, planes, 0.0)


def squeeze_weight(held: np.ndarray, ramp_frames: int) -> np.ndarray:
    """(T,) 0 outside the held runs; inside each, rising linearly from its start and falling to its end over
    `ramp_frames` (a run shorter than two ramps peaks in its middle)."""
    held = np.asarray(held, dtype=bool)
    out = np.zeros(len(held))
    for a, b in mask_segments(held):
        t = np.arange(a, b + 1)
        out[a:b + 1] = np.clip(np.minimum(t - a + 1, b + 1 - t) / (ramp_frames + 1), 0.0, 1.0)
    return out


def blend_weight(held: np.ndarray, ramp_frames: int) -> np.ndarray:
    """(T,) 1 on held frames, easing (smoothstep) to 0 over `ramp_frames` before and after each run of them."""
    held = np.asarray(held, dtype=bool)
    out = held.astype(np.float64)
    for a, b in mask_segments(held):
        for i in range(1, ramp_frames + 1):
            x = 1.0 - i / (ramp_frames + 1)
            w = x * x * (3.0 - 2.0 * x)
            for t in (a - i, b + i):
                if 0 <= t < len(out):
                    out[t] = max(out[t], w)
    return out


def read_episode(targets: RobotTargets, need: np.ndarray, first: int, last: int, sides: tuple[str, ...],
                 hand_links: dict[str, tuple[str, ...]], settings: GraspSettings) -> Episode:
    """The planner's view of frames first..last of the targets (object frame of the first frame)."""
    frames = np.arange(first, last + 1)
    names = list(targets.link_names)
    pos, quat = targets.object_pos[frames], wxyz_to_xyzw(targets.object_quat_wxyz[frames])
    local = lambda cols: to_object_frame(targets.pos[frames][:, cols], pos, quat)  # noqa: E731
    held = {side: need[frames, SIDES.index(side)] for side in sides}
    hands = {side: local([names.index(n) for n in hand_links[side]])[held[side]].mean(0) for side in sides}
    shoulders = {side: names.index(targets.link_names[targets.human_names.index(f"{side[0].upper()}_Shoulder")])
                 for side in sides}
    arms = {side: local([shoulders[side]])[:, 0].mean(0) for side in sides}
    rot = Rotation.from_quat(quat[0]).as_matrix()
    shift = np.append(pos[-1, :2] - pos[0, :2], 0.0)
    moving = np.linalg.norm(shift) > settings.move_m
    return Episode(first, last, held, hands, arms, rot.T @ np.array([0.0, 0.0, 1.0]),
                   bool(pos[:, 2].max() - pos[0, 2] > settings.lift_m),
                   rot.T @ shift / np.linalg.norm(shift) if moving else np.zeros(3))


def episode_grips(episode: Episode, faces: list[Face], planes: HullPlanes, com: np.ndarray,
                  geometries: dict[str, HandGeometry], settings: GraspSettings) -> list[Grip]:
    """The grips of one episode (none where it keeps the human's placement)."""
    s, kind = settings, episode_kind(episode, com)
    span = (episode.first, episode.last)
    if kind == "hook":
        face = leading_face(faces, episode, thinner_than=0.12)
        if face is None:
            kind = "claw" if len(episode.held) == 2 else None
        else:
            lateral = np.cross(episode.up, face.normal)
            lateral /= np.linalg.norm(lateral)
            centre = np.mean([episode.palm(side) for side in episode.held], axis=0)
            points = side_by_side(episode, face.clamp(centre, s.edge_margin_m), lateral)
            grips = []
            for side, point in points.items():
                point = face.clamp(point, s.edge_margin_m)
                point, rotation, wrist = hook_pose(geometries[side], face, point, episode.up, planes, s.palm_gap_m,
                                                   s.hook_below_m)
                closure = geometries[side].finger_closures(rotation, wrist, planes, 0.0, s.max_closure)
                into = episode.motion + episode.up  # pull toward the hands and lift the edge
                grips.append(Grip(side, "hook", span, face, point, rotation, wrist, closure, into / np.linalg.norm(into)))
            return grips
    if kind == "push":
        top = top_face(faces, episode.up)
        if top is None:
            return []
        lateral = np.cross(episode.up, episode.motion)
        grips = []
        for side, point in side_by_side(episode, com, lateral / np.linalg.norm(lateral)).items():
            point, rotation, wrist = push_pose(geometries[side], top, point, episode.motion, planes, s.palm_gap_m)
            closure = geometries[side].finger_closures(rotation, wrist, planes, 0.0, s.max_closure)
            into = episode.motion - 0.25 * episode.up  # mostly ahead: pressing down adds floor friction
            grips.append(Grip(side, "push", span, top, point, rotation, wrist, closure, into / np.linalg.norm(into)))
        return grips
    if kind != "claw":
        return []
    chosen = opposing_faces(faces, episode, com, s)
    if chosen is None:
        return []
    grips = []
    for side, face in chosen[0].items():
        geo, point = geometries[side], chosen[1][side]
        rotation = turn_palm(geo, fitted_rotation(geo, episode.hands[side]), -face.normal)
        if (rotation @ geo.axis) @ (point - episode.arms[side]) <= 0:  # fingers back toward the shoulder
            rotation = finger_rotation(geo, face, finger_direction(face, point, episode.arms[side], episode.up))
        rotation, wrist = claw_pose(geo, face, point, rotation, s.closure, planes, s.palm_gap_m)
        # the longest finger's pad sets the wrist; the others close further until theirs reach the face too
        closure = geo.finger_closures(rotation, wrist, planes, s.closure, s.max_closure, s.palm_gap_m + 1e-4)
        grips.append(Grip(side, "claw", span, face, point, rotation, wrist, closure, -face.normal))
    return grips


def plan_grasps(targets: RobotTargets, need: np.ndarray, pieces: list[np.ndarray], com: np.ndarray,
                geometries: dict[str, HandGeometry], settings: GraspSettings | None = None) -> GraspPlan:
    """The grips of every grip episode of a clip's robot-space `targets`: `need` (T, 2) the frames each hand must
    touch the object (hand_contact_need), `pieces` the vertices of the convex pieces the simulation collides with
    and `com` the centre of mass, object frame; `geometries` per side (hand_geometry)."""
    s = settings or GraspSettings()
    T = targets.num_frames
    rot = Rotation.from_quat(wxyz_to_xyzw(targets.object_quat_wxyz)).as_matrix()
    faces, planes = object_faces(pieces), HullPlanes.from_pieces(pieces)
    plan = GraspPlan([], {}, {}, {}, {}, {}, {}, {})
    for side, geo in geometries.items():
        plan.links[side] = geo.links
        plan.blend[side], plan.squeeze[side] = np.zeros(T), np.zeros(T)
        plan.link_pos[side] = np.zeros((T, len(geo.links), 3))
        plan.channel_angles[side], plan.press[side] = np.zeros((T, 6)), np.zeros((T, 6))
        plan.into[side] = np.zeros((T, 3))
    ramp = max(int(round(s.blend_s * targets.fps)), 1)
    press_ramp = max(int(round(s.squeeze_s * targets.fps)), 1)
    frames = np.arange(T)
    for first, last, sides in grip_episodes(need):
        sides = tuple(side for side in sides if side in geometries)
        if not sides:
            continue
        episode = read_episode(targets, need, first, last, sides, plan.links, s)
        both = np.logical_and.reduce(list(episode.held.values()))
        grips = episode_grips(episode, faces, planes, com, geometries, s)
        plan.grips += grips
        for grip in grips:
            held = np.isin(frames, first + np.flatnonzero(episode.held[grip.side]))
            _write_grip(plan, grip, geometries[grip.side], blend_weight(held, ramp), rot, targets.object_pos, s)
            if len(sides) == 2:  # one hand squeezing alone slides the object away from the other
                held &= np.isin(frames, first + np.flatnonzero(both))
            plan.squeeze[grip.side] = np.maximum(plan.squeeze[grip.side], squeeze_weight(held, press_ramp))
    return plan


def _write_grip(plan: GraspPlan, grip: Grip, geometry: HandGeometry, weight: np.ndarray, rot: np.ndarray,
                obj: np.ndarray, s: GraspSettings) -> None:
    """Fill the plan's per-frame arrays of one grip where its blend weight is larger than what is there."""
    side = grip.side
    frames = np.flatnonzero(weight > plan.blend[side])
    if not len(frames):
        return
    w = weight[frames]
    links = grip.wrist + geometry.at(grip.closure)[0] @ grip.rotation.T
    local = links[None] + ((1.0 - w) * s.approach_m)[:, None, None] * grip.face.normal
    plan.blend[side][frames] = w
    plan.link_pos[side][frames] = np.einsum("tij,tkj->tki", rot[frames], local) + obj[frames, None]
    plan.channel_angles[side][frames] = geometry.channel_angles(grip.closure)
    plan.press[side][frames] = s.press * (geometry.closed_rad - geometry.open_rad)
    plan.into[side][frames] = np.einsum("tij,j->ti", rot[frames], grip.into)


def apply_plan(targets: RobotTargets, plan: GraspPlan, weight: float) -> RobotTargets:
    """The targets with each side's hand links moved toward its grips by the blend weight and weighted `weight`
    (an IK weight) while they grip."""
    pos, weights = targets.pos.copy(), targets.weight.copy()
    names = list(targets.link_names)
    for side, links in plan.links.items():
        cols = [names.index(n) for n in links]
        w = plan.blend[side][:, None]
        pos[:, cols] = (1.0 - w[..., None]) * pos[:, cols] + w[..., None] * plan.link_pos[side]
        weights[:, cols] = (1.0 - w) * weights[:, cols] + w * weight
    return replace(targets, pos=pos, weight=weights)

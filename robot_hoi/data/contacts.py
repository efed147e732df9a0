"""Contact inference from object dynamics and human-object distances (InterMimic supp. Sec. C.1).

A human-induced force acts on the object when
  (i)  it is airborne but its acceleration is far from free fall, or
  (ii) it rests on the floor but moves in a way friction alone cannot explain (sliding without decelerating at
       mu * g, or turning),
and a body touches it when (iii) the closest body is within `touch_distance` of its surface.
Contact frames: (i or ii, with some body within `max_force_distance`) or iii. In a contact frame the adaptive
threshold is sigma = max(min distance + `adaptive_margin`, `touch_distance`); a body closer than sigma is a
contact (+1), and a hand counts as one unit (any hand part in contact -> the wrist and all its fingers, as the
stored labels and InterMimic's hand-interaction discovery do). A body farther than `far_distance` is -1 (contact
there is penalised) unless it is a foot on the floor; everything else is 0 (neutral).

We have joint centres, not the body surface: each body is approximated by its bone segment (joint to first
child joint) thickened by a rough radius (BODY_RADIUS_M), and distances are measured from that surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import savgol_filter
from scipy.spatial.transform import Rotation

from robot_hoi.data.layout import (
    BODY_NAMES,
    BODY_PARENTS,
    FEET,
    L_HAND,
    LABEL_CONTACT,
    LABEL_FAR,
    LABEL_UNKNOWN,
    NUM_BODIES,
    R_HAND,
)
from robot_hoi.data.objects import ObjectAsset, to_local, to_world
from robot_hoi.data.segments import format_segments

GRAVITY = np.array([0.0, 0.0, -9.81])

# Rough half-thickness (m) of each body part around its bone segment, by name (L_/R_ stripped, digits ignored).
_RADIUS_BY_PART = {
    "Pelvis": 0.10, "Hip": 0.07, "Knee": 0.05, "Ankle": 0.035, "Toe": 0.02, "Torso": 0.10, "Spine": 0.10,
    "Chest": 0.10, "Neck": 0.05, "Head": 0.09, "Thorax": 0.05, "Shoulder": 0.045, "Elbow": 0.035,
    "Wrist": 0.015, "Index": 0.008, "Middle": 0.008, "Pinky": 0.007, "Ring": 0.008, "Thumb": 0.009,
}  # fmt: skip
BODY_RADIUS_M = np.array([_RADIUS_BY_PART[n.split("_")[-1].rstrip("0123456789")] for n in BODY_NAMES])
# Each body's segment ends at its first child joint (leaves: a point).
SEGMENT_END = np.array(
    [next((c for c in range(NUM_BODIES) if BODY_PARENTS[c] == j), j) for j in range(NUM_BODIES)]
)
_SEGMENT_STEPS = np.array([0.0, 0.25, 0.5, 0.75])


@dataclass(frozen=True)
class ContactParams:
    ground_tolerance_m: float = 0.02  # lowest object point below this: resting on the floor
    accel_tolerance: float = 3.0  # m/s^2 away from free fall / friction-only motion counts as a push
    friction_coefficient: float = 0.5  # expected deceleration of a released sliding object: mu * g
    moving_speed: float = 0.05  # m/s: slower counts as static
    turning_speed: float = 0.3  # rad/s: a floor object turning faster is being turned
    touch_distance: float = 0.02  # m, body surface to object surface (the stored labels' 2 cm)
    adaptive_margin: float = 0.005  # m, as in the paper
    far_distance: float = 0.10  # m, sigma_p of the contact penalty
    max_force_distance: float = 0.15  # m: a force with nobody this close is an artifact, not a contact
    smoothing_window_s: float = 0.3  # Savitzky-Golay window for velocities / accelerations
    foot_ground_margin: float = 0.03  # m above the foot's lowest height in the clip: on the floor


@dataclass
class ContactEstimate:
    contact: np.ndarray  # (T,) bool
    body_contact: np.ndarray  # (T, 52) int8: +1 contact, -1 far, 0 neutral
    force: np.ndarray  # (T,) bool: object dynamics need a human-induced force
    airborne: np.ndarray  # (T,) bool
    body_distance: np.ndarray  # (T, 52) m, approximate body surface to object surface (0 when inside)
    min_distance: np.ndarray  # (T,) m
    threshold: np.ndarray  # (T,) m, adaptive sigma (NaN outside contact frames)
    problems: list[str]


def _window(fps: float, seconds: float, num_frames: int) -> int:
    w = max(5, int(round(seconds * fps)) | 1)
    if w > num_frames:
        w = num_frames if num_frames % 2 else num_frames - 1
    return w


def object_motion(obj: ObjectAsset, pos: np.ndarray, quat_xyzw: np.ndarray, fps: float, window_s: float):
    """(lowest point z (T,), centre velocity (T,3), centre acceleration (T,3), angular speed (T,))."""
    num_frames = len(pos)
    lowest = to_world(obj.hull_vertices(), pos, quat_xyzw)[..., 2].min(axis=1)
    centre_local = 0.5 * (obj.vertices.min(axis=0) + obj.vertices.max(axis=0))
    centre = Rotation.from_quat(quat_xyzw).apply(centre_local) + pos
    if num_frames < 5:
        zeros = np.zeros((num_frames, 3))
        return lowest, zeros, zeros, np.zeros(num_frames)
    w = _window(fps, window_s, num_frames)
    vel = savgol_filter(centre, w, 2, deriv=1, delta=1.0 / fps, axis=0, mode="interp")
    acc = savgol_filter(centre, w, 2, deriv=2, delta=1.0 / fps, axis=0, mode="interp")
    rot = Rotation.from_quat(quat_xyzw)
    step = (rot[1:] * rot[:-1].inv()).magnitude() * fps
    omega = uniform_filter1d(np.concatenate([step[:1], step]), size=w, mode="nearest")
    return lowest, vel, acc, omega


def body_surface_distance(
    body_pos: np.ndarray, obj: ObjectAsset, object_pos: np.ndarray, object_quat_xyzw: np.ndarray
) -> np.ndarray:
    """(T, 52) distance (m) from each body part (bone segment thickened by BODY_RADIUS_M) to the object surface."""
    start = body_pos[:, :, None, :]
    end = body_pos[:, SEGMENT_END, None, :]
    points = start + _SEGMENT_STEPS[None, None, :, None] * (end - start)  # (T, 52, S, 3)
    num_frames = body_pos.shape[0]
    local = to_local(points.reshape(num_frames, -1, 3), object_pos, object_quat_xyzw)
    dist = obj.surface_distance(local).reshape(num_frames, NUM_BODIES, len(_SEGMENT_STEPS)).min(axis=2)
    return np.maximum(dist - BODY_RADIUS_M, 0.0)


def label_contacts(
    body_pos: np.ndarray, obj: ObjectAsset, object_pos: np.ndarray, object_quat_xyzw: np.ndarray, fps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Labels by the rule the stored InterAct labels follow: (contact flag (T,) int8, per-body (T, 52) int8).

    Body: +1 within 2 cm of the object, -1 beyond 10 cm, else 0 (feet on the floor: 0); a hand is one unit.
    Flag: (some body within 2 cm, or the object airborne and not in free fall) and some body within 10 cm.
    """
    p = ContactParams()
    distance = body_surface_distance(body_pos, obj, object_pos, object_quat_xyzw)
    body = np.full(distance.shape, LABEL_UNKNOWN, dtype=np.int8)
    body[distance > p.far_distance] = LABEL_FAR
    body[distance < p.touch_distance] = LABEL_CONTACT
    for hand in (L_HAND, R_HAND):
        touching = (body[:, list(hand)] == LABEL_CONTACT).any(axis=1)
        body[np.ix_(touching, list(hand))] = LABEL_CONTACT
    feet = list(FEET)
    foot_z = body_pos[:, feet, 2]
    grounded = foot_z < foot_z.min(axis=0, keepdims=True) + p.foot_ground_margin
    body[:, feet] = np.where(grounded & (body[:, feet] == LABEL_FAR), LABEL_UNKNOWN, body[:, feet])
    lowest, _, acc, _ = object_motion(obj, object_pos, object_quat_xyzw, fps, p.smoothing_window_s)
    held = (lowest > p.ground_tolerance_m) & (np.linalg.norm(acc - GRAVITY, axis=1) > p.accel_tolerance)
    min_distance = distance.min(axis=1)
    flag = ((min_distance < p.touch_distance) | held) & (min_distance < p.far_distance)
    return flag.astype(np.int8), body


def infer_contacts(
    body_pos: np.ndarray,
    obj: ObjectAsset,
    object_pos: np.ndarray,
    object_quat_xyzw: np.ndarray,
    fps: float,
    params: ContactParams | None = None,
) -> ContactEstimate:
    p = params or ContactParams()
    num_frames = body_pos.shape[0]
    distance = body_surface_distance(body_pos, obj, object_pos, object_quat_xyzw)
    min_distance = distance.min(axis=1)
    lowest, vel, acc, omega = object_motion(obj, object_pos, object_quat_xyzw, fps, p.smoothing_window_s)

    airborne = lowest > p.ground_tolerance_m
    not_free_fall = np.linalg.norm(acc - GRAVITY, axis=1) > p.accel_tolerance
    speed_xy = np.linalg.norm(vel[:, :2], axis=1)
    direction = vel[:, :2] / np.maximum(speed_xy, 1e-9)[:, None]
    friction_only = -p.friction_coefficient * 9.81 * direction
    pushed = np.linalg.norm(acc[:, :2] - friction_only, axis=1) > p.accel_tolerance
    sliding = speed_xy > p.moving_speed
    on_floor = ~airborne
    force = (
        (airborne & not_free_fall) | (on_floor & sliding & pushed) | (on_floor & (omega > p.turning_speed))
    )

    near_enough = min_distance < p.max_force_distance
    touching = min_distance < p.touch_distance
    contact = (force & near_enough) | touching
    threshold = np.where(contact, np.maximum(min_distance + p.adaptive_margin, p.touch_distance), np.nan)

    body = np.full((num_frames, distance.shape[1]), LABEL_UNKNOWN, dtype=np.int8)
    body[distance > p.far_distance] = LABEL_FAR
    close = contact[:, None] & (distance < np.nan_to_num(threshold, nan=-1.0)[:, None])
    for hand in (L_HAND, R_HAND):
        close[:, list(hand)] |= close[:, list(hand)].any(axis=1, keepdims=True)
    body[close] = LABEL_CONTACT
    feet = list(FEET)
    foot_z = body_pos[:, feet, 2]
    grounded = foot_z < foot_z.min(axis=0, keepdims=True) + p.foot_ground_margin
    body[:, feet] = np.where(grounded & (body[:, feet] == LABEL_FAR), LABEL_UNKNOWN, body[:, feet])

    problems = []
    orphan = force & ~near_enough
    if orphan.any():
        problems.append(
            f"object moves under an external force with no body within {p.max_force_distance:g} m at frames "
            f"{format_segments(orphan)} (floating contact or object-tracking error)"
        )
    return ContactEstimate(
        contact=contact,
        body_contact=body,
        force=force,
        airborne=airborne,
        body_distance=distance,
        min_distance=min_distance,
        threshold=threshold,
        problems=problems,
    )


def hand_contact_need(clip, num_frames: int | None = None) -> np.ndarray:
    """(T, 2) bool, left / right: the hand must touch the object (any body of the hand, wrist + fingers, labelled
    +1). Where the clip carries contacts inferred from the object's dynamics (supp. C.1) and they disagree with the
    stored labels, inference wins: a hand inferred in contact must touch, one inferred far (-1 on all its bodies)
    need not; neutral frames keep the stored label. Training's contact rule, the physics gate and the grasp
    planner all read this."""
    num_frames = len(clip.body_contact) if num_frames is None else num_frames
    hands = [list(L_HAND), list(R_HAND)]
    stored = np.asarray(clip.body_contact)[:num_frames]
    need = np.stack([(stored[:, ids] > 0).any(1) for ids in hands], axis=1)
    inferred = getattr(clip, "inferred_body_contact", None)
    if inferred is None or not np.asarray(inferred).any():
        return need
    inferred = np.asarray(inferred)[:num_frames]
    touch = np.stack([(inferred[:, ids] > 0).any(1) for ids in hands], axis=1)
    far = np.stack([(inferred[:, ids] < 0).all(1) for ids in hands], axis=1)
    return np.where(touch, True, np.where(far, False, need))

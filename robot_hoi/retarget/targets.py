"""Robot-space targets from a human-object clip: where each robot link should be, how much it matters.

The mapping (the team's design; every number below is a `TargetMapping` field):

* Scale. s = robot_height / subject_height (G1: 1.32 m), unless the caller passes `scale`.
* Body. The pelvis' horizontal path is scaled about its first position, root'_xy = root_0 + s (root_xy - root_0),
  so strides match the robot's legs and planted feet do not slide (keeping the human's path made feet slide by
  (1 - s) x the distance walked); heights and the body's shape around the root are scaled:
  p' = [root'_xy + s (p_xy - root_xy),  s p_z].
* Object. It keeps its real size; only its height above its resting height is scaled: z' = z_rest + s (z - z_rest),
  z_rest = its height in the first frame. Horizontally the gap between the pelvis and the object's surface is
  scaled (not the distance to its centre): with dir = the unit vector pelvis -> object centre and r = the object's
  extent from its centre toward the pelvis,  o'_xy = root'_xy + dir (s (|o_xy - root_xy| - r) + r). A resting
  object stays put while the robot walks to it, and a real-size box is not pushed into the robot's smaller
  reach. Its orientation is unchanged.
* Anchoring. A link near the object follows the object instead of the scaled body, so the hands stay on a
  real-size object while the rest of the robot is scaled. For link i at frame t, with d = the human link's
  distance to the object surface (the object's sample points moved by its pose):
      a = clip(1 - d / anchor_radius, 0, 1)          (anchor_radius 0.15 m)
  or, with anchor_mode "contact" and per-body contact labels in the clip, a = 1 where the label says contact,
  0 where it says far, the distance weight otherwise. The anchored point is the human link expressed in the
  human-space object frame and mapped back through the robot-space object pose:
      p_anchor = R_obj' R_obj^T (p - o) + o'
  and the target is  a p_anchor + (1 - a) p'. Mocap hands sink into objects (fingertip joints 2-5 cm deep in
  OMOMO) and the simulation collides with the object's convex hull, so an anchored point inside the hull (or
  closer than object_clearance to it) is first moved out along the nearest hull face (object_contact.py).
* Weights. Each link's IK weight is its group's weight plus anchor_weight * a: a hand on the object matters more
  than a hand in the air. Free fingertips weigh little (the Inspire hand is longer than a scaled human hand, so
  free fingertips would only pull the wrist off its target); anchored ones weigh like a wrist on the object.
  The anchor weights a are returned too (rewards and the report use them).

Quaternions: the clip stores xyzw (scipy); the targets store MuJoCo's wxyz, named so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.data.layout import BODY_INDEX
from robot_hoi.data.objects import check_object_collision
from robot_hoi.errors import DataError
from robot_hoi.retarget.object_contact import HullPlanes

# Human body name -> link group (used for weights and for the residual report).
_GROUP_OF_NAME = {
    "Pelvis": "pelvis",
    "Hip": "legs", "Knee": "legs",
    "Ankle": "feet", "Toe": "feet",
    "Torso": "torso", "Spine": "torso", "Chest": "torso", "Neck": "torso", "Thorax": "torso",
    "Head": "head",
    "Shoulder": "arms", "Elbow": "arms",
    "Wrist": "wrists",
}  # fmt: skip
GROUPS = ("pelvis", "legs", "feet", "torso", "head", "arms", "wrists", "fingers")


def link_group(human_name: str) -> str:
    """'L_Knee' -> 'legs', 'R_Index3' -> 'fingers', 'Pelvis' -> 'pelvis'."""
    base = human_name[2:] if human_name[:2] in ("L_", "R_") else human_name
    if base in _GROUP_OF_NAME:
        return _GROUP_OF_NAME[base]
    if base.rstrip("0123456789") in ("Index", "Middle", "Ring", "Pinky", "Thumb"):
        return "fingers"
    raise DataError(f"no link group for human body '{human_name}'")


ANCHOR_MODES = ("distance", "contact")


def hand_side(human_name: str) -> str | None:
    """'left' / 'right' for bodies of a hand (wrist and fingers), else None."""
    if link_group(human_name) not in ("wrists", "fingers"):
        return None
    return "left" if human_name.startswith("L_") else "right"


@dataclass(frozen=True)
class TargetMapping:
    """How human positions become robot targets (see the module docstring)."""

    anchor_radius: float = 0.15  # m: links closer than this to the object surface follow the object
    anchor_mode: str = "distance"  # "distance" | "contact" (use the clip's per-body labels where they exist)
    anchor_weight: float = 2.0  # added to a link's weight in proportion to its anchor weight a
    scale_object_height: bool = True  # False keeps the object's real height (then z_rest plays no role)
    object_clearance: float | None = 0.01  # m: anchored points inside the object's hull go out to this; None: off
    # Planted feet: a foot link within pin_height of its lowest height and slower than pin_speed (robot space) is
    # on the floor; over each such stretch its target is held at the stretch's mean position and its IK weight
    # raised by pin_weight, so the IK solution does not slide it either. pin_weight 0: off.
    pin_height: float = 0.03  # m
    pin_speed: float = 0.25  # m/s
    pin_weight: float = 10.0
    # The Inspire hand is ~1.65x a human hand (wrist to fingertip 0.25 m vs 0.15 m): mapping the human wrist and
    # fingertips 1:1 puts the robot's fingertips on the human's and its wrist ~10 cm short, so a side grip lands
    # on the box's top edge with the palm off the face. With hand_size_fit, each hand's links are scaled about the
    # human palm (wrist-to-middle-knuckle midpoint) to the robot hand's size first, so the palms coincide.
    hand_size_fit: bool = True
    # What the simulation collides with (and the IK keeps the hands out of): "hull", the mesh's convex hull, or
    # "decomposed", its convex pieces (ObjectAsset.convex_parts), so a hand can reach under a table's top.
    object_collision: str = "hull"
    group_weights: dict[str, float] = field(
        default_factory=lambda: {
            "pelvis": 3.0, "legs": 1.0, "feet": 2.0, "torso": 1.0, "head": 0.3,
            "arms": 0.6, "wrists": 1.0, "fingers": 0.05,
        }
    )  # fmt: skip

    def __post_init__(self) -> None:
        if self.anchor_mode not in ANCHOR_MODES:
            raise DataError(f"anchor_mode must be 'distance' or 'contact', not '{self.anchor_mode}'")
        if self.anchor_radius <= 0:
            raise DataError(f"anchor_radius must be > 0, got {self.anchor_radius}")
        check_object_collision(self.object_collision)
        missing = set(GROUPS) - set(self.group_weights)
        if missing:
            raise DataError(f"group_weights lacks {sorted(missing)}")


@dataclass
class RobotTargets:
    """Per-frame robot-space targets for the link_map entries (robot link i <- human body human_names[i])."""

    fps: float
    link_names: tuple[str, ...]  # robot bodies or sites
    human_names: tuple[str, ...]
    pos: np.ndarray  # (T, L, 3) target world positions
    weight: np.ndarray  # (T, L) IK weights
    anchor: np.ndarray  # (T, L) anchor weights a in [0, 1]
    object_pos: np.ndarray  # (T, 3) robot-space object origin
    object_quat_wxyz: np.ndarray  # (T, 4)
    root_quat_wxyz: np.ndarray  # (T, 4) human pelvis orientation (same axes as the G1 pelvis: x fwd, z up)
    scale: float
    human_pos: np.ndarray  # (T, L, 3) the human links, real scale (for reports)
    human_surface_dist: np.ndarray  # (T, L) human link to object surface, m
    human_object_pos: np.ndarray  # (T, 3) the object's real (human-space) position; orientation as object_quat
    object_points_local: np.ndarray  # (P, 3) object surface samples in the object frame
    object_local_distance: Callable[[np.ndarray], np.ndarray] | None = None  # dense surface distance, if known
    object_hull: HullPlanes | None = None  # what the simulation collides with (hull or pieces)
    object_mass_kg: float | None = None  # when the clip knows it (the synthetic boxes)

    def robot_surface_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (T, L) of robot-space points (T, L, 3) to the robot-space object surface."""
        return surface_distance(points, self.object_pos, wxyz_to_xyzw(self.object_quat_wxyz),
                                self.object_points_local, self.object_local_distance)

    @property
    def num_frames(self) -> int:
        return int(self.pos.shape[0])

    @property
    def groups(self) -> tuple[str, ...]:
        return tuple(link_group(n) for n in self.human_names)


def to_object_frame(points: np.ndarray, pos: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """World points (T, L, 3) -> object-local points for object poses (T, 3) + (T, 4 xyzw)."""
    mats = Rotation.from_quat(quat_xyzw).as_matrix()
    return np.einsum("tji,tlj->tli", mats, points - pos[:, None, :])


def surface_distance(
    points: np.ndarray,
    pos: np.ndarray,
    quat_xyzw: np.ndarray,
    points_local: np.ndarray,
    local_distance: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """Distance (T, L) from world points (T, L, 3) to the object surface.

    `local_distance` (e.g. ObjectAsset.surface_distance: dense samples, ~1 cm) is used when given; otherwise the
    nearest of the object's sample points `points_local` (P, 3), which overestimates by up to half their spacing.
    """
    local = to_object_frame(points, pos, quat_xyzw)
    if local_distance is not None:
        return np.asarray(local_distance(local), dtype=np.float64)
    sq = (
        np.einsum("tli,tli->tl", local, local)[:, :, None]
        + np.einsum("pi,pi->p", points_local, points_local)[None, None, :]
        - 2.0 * np.einsum("tli,pi->tlp", local, points_local)
    )
    return np.sqrt(np.maximum(sq.min(axis=2), 0.0))


def scale_root_path(root_xy: np.ndarray, s: float) -> np.ndarray:
    """root'_xy = root_0 + s (root_xy - root_0) for the pelvis path (T, 2)."""
    return root_xy[:1] + s * (root_xy - root_xy[:1])


def scale_body(body_pos: np.ndarray, root_xy: np.ndarray, s: float) -> np.ndarray:
    """p' = [root'_xy + s (p_xy - root_xy), s p_z] for positions (T, N, 3) and the human root path (T, 2)."""
    out = np.empty_like(body_pos)
    out[..., :2] = scale_root_path(root_xy, s)[:, None, :] + s * (body_pos[..., :2] - root_xy[:, None, :])
    out[..., 2] = s * body_pos[..., 2]
    return out


def place_object_xy(object_xy: np.ndarray, object_quat_xyzw: np.ndarray, points_local: np.ndarray,
                    root_xy: np.ndarray, s: float) -> np.ndarray:
    """o'_xy = root'_xy + dir (s (|o - root| - r) + r): the pelvis-to-surface gap scaled, the object real size."""
    offset = object_xy - root_xy
    dist = np.linalg.norm(offset, axis=-1, keepdims=True)
    direction = offset / np.maximum(dist, 1e-9)
    points = np.einsum("tij,pj->tpi", Rotation.from_quat(object_quat_xyzw).as_matrix(), points_local)[..., :2]
    extent = np.clip((points * -direction[:, None, :]).sum(-1).max(-1, keepdims=True), 0.0, dist)
    return scale_root_path(root_xy, s) + direction * (s * (dist - extent) + extent)


def scale_object(object_pos: np.ndarray, s: float, scale_height: bool = True) -> np.ndarray:
    """z' = z_rest + s (z - z_rest), z_rest = first-frame height; x, y unchanged."""
    out = np.array(object_pos, dtype=np.float64, copy=True)
    if scale_height:
        z_rest = out[0, 2]
        out[:, 2] = z_rest + s * (out[:, 2] - z_rest)
    return out


def anchor_weights(
    surface_dist: np.ndarray, radius: float, contact_labels: np.ndarray | None = None
) -> np.ndarray:
    """a = clip(1 - d / radius, 0, 1); with labels (+1 contact, -1 far, 0 unknown) those override where set."""
    a = np.clip(1.0 - surface_dist / radius, 0.0, 1.0)
    if contact_labels is not None:
        a = np.where(contact_labels > 0, 1.0, np.where(contact_labels < 0, 0.0, a))
    return a


def map_positions(
    human_pos: np.ndarray,
    root_xy: np.ndarray,
    object_pos: np.ndarray,
    object_quat_xyzw: np.ndarray,
    points_local: np.ndarray,
    s: float,
    mapping: TargetMapping,
    contact_labels: np.ndarray | None = None,
    local_distance: Callable[[np.ndarray], np.ndarray] | None = None,
    hull: HullPlanes | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The core of the mapping on plain arrays.

    human_pos (T, L, 3) real-scale link positions; root_xy (T, 2); object pose (T, 3) + (T, 4 xyzw); points_local
    (P, 3); contact_labels (T, L) or None; local_distance: see `surface_distance`; hull: the object's convex hull
    for mapping.object_clearance.
    Returns (targets (T, L, 3), anchor (T, L), robot object pos (T, 3), human surface distance (T, L)).
    """
    scaled = scale_body(human_pos, root_xy, s)
    obj_robot = scale_object(object_pos, s, mapping.scale_object_height)
    obj_robot[:, :2] = place_object_xy(object_pos[:, :2], object_quat_xyzw, points_local, root_xy, s)
    dist = surface_distance(human_pos, object_pos, object_quat_xyzw, points_local, local_distance)
    a = anchor_weights(dist, mapping.anchor_radius, contact_labels if mapping.anchor_mode == "contact" else None)
    rot_r = Rotation.from_quat(object_quat_xyzw).as_matrix()  # the object keeps its orientation
    local = to_object_frame(human_pos, object_pos, object_quat_xyzw)
    if hull is not None and mapping.object_clearance is not None:
        local = hull.push_out(local, mapping.object_clearance)
    anchored = np.einsum("tij,tlj->tli", rot_r, local) + obj_robot[:, None, :]
    targets = a[..., None] * anchored + (1.0 - a[..., None]) * scaled
    return targets, a, obj_robot, dist


def planted(foot_pos: np.ndarray, fps: float, height: float, speed: float) -> np.ndarray:
    """(T, F) bool: each foot link (T, F, 3) near its lowest height and slow horizontally."""
    low = foot_pos[..., 2] < foot_pos[..., 2].min(axis=0) + height
    vel = np.linalg.norm(np.gradient(foot_pos[..., :2], 1.0 / fps, axis=0), axis=-1)
    return low & (vel < speed)


def pin_feet(pos: np.ndarray, weight: np.ndarray, feet: list[int], fps: float, mapping: TargetMapping) -> None:
    """In place: over each planted stretch of a foot link, its target is the stretch's mean position (a planted
    foot does not move) and its weight rises by pin_weight."""
    if mapping.pin_weight <= 0 or not feet:
        return
    down = planted(pos[:, feet], fps, mapping.pin_height, mapping.pin_speed)
    for column, link in enumerate(feet):
        flags = np.concatenate([[False], down[:, column], [False]])
        starts, ends = np.flatnonzero(~flags[:-1] & flags[1:]), np.flatnonzero(flags[:-1] & ~flags[1:])
        for a, b in zip(starts, ends, strict=True):
            pos[a:b, link] = pos[a:b, link].mean(axis=0)
            weight[a:b, link] += mapping.pin_weight


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    return np.concatenate([q[..., 3:4], q[..., :3]], axis=-1)


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    return np.concatenate([q[..., 1:4], q[..., 0:1]], axis=-1)


def fit_hand_size(body_pos: np.ndarray, human_pos: np.ndarray, human_names: list[str],
                  hand_length: dict[str, float]) -> np.ndarray:
    """human_pos (T, L, 3) with each hand's mapped links (wrist, fingertips) scaled about that hand's palm centre
    (the wrist-to-middle-knuckle midpoint) by robot / human wrist-to-fingertip length (`hand_length[side]`, side
    as `hand_side` names it, over the clip's mean distance from the wrist to the mapped fingertips)."""
    out = human_pos.copy()
    for side, length in hand_length.items():
        links = [i for i, n in enumerate(human_names) if hand_side(n) == side]
        wrists = [human_names[i] for i in links if link_group(human_names[i]) == "wrists"]
        tips = [i for i in links if link_group(human_names[i]) == "fingers"]
        if len(wrists) != 1 or not tips:
            continue
        wrist = body_pos[:, BODY_INDEX[wrists[0]]]
        human_length = float(np.linalg.norm(human_pos[:, tips] - wrist[:, None], axis=-1).mean())
        if human_length <= 1e-6:
            continue
        palm = 0.5 * (wrist + body_pos[:, BODY_INDEX[wrists[0].replace("Wrist", "Middle1")]])
        out[:, links] = palm[:, None] + (length / human_length) * (human_pos[:, links] - palm[:, None])
    return out


def targets_from_clip(clip, cfg, scale: float | None = None, mapping: TargetMapping | None = None,
                      hand_length: dict[str, float] | None = None) -> RobotTargets:
    """Robot targets for every `cfg.link_map` entry of an HOIClip (robot_hoi.data).

    `cfg` needs `robot_height` (m) and `link_map` {robot body/site: human body name}. `hand_length`: the robot's
    mean wrist-to-fingertip distance per side ("left", "right"), for `mapping.hand_size_fit` (off where not given).
    """
    mapping = mapping or TargetMapping()
    link_map = dict(cfg.link_map)
    unknown = [h for h in link_map.values() if h not in BODY_INDEX]
    if unknown:
        raise DataError(f"embodiment link_map names unknown human bodies: {', '.join(unknown)}")
    human_idx = np.array([BODY_INDEX[h] for h in link_map.values()], dtype=np.int64)
    if scale is None:
        height = float(clip.subject_height_m)
        if not height > 0:
            raise DataError(f"clip {getattr(clip, 'name', '')!r}: subject height {height} m is not usable")
        scale = float(cfg.robot_height) / height
    if not 0.1 < scale < 10.0:
        raise DataError(f"human->robot scale {scale:.3f} is implausible")

    if getattr(clip, "object", None) is None:
        raise DataError(f"clip {getattr(clip, 'name', '')!r} has no object asset (mesh and surface samples); "
                        "retargeting anchors the hands to the object and needs it")
    body_pos = np.asarray(clip.body_pos, dtype=np.float64)
    obj_pos = np.asarray(clip.object_pos, dtype=np.float64)
    obj_quat_xyzw = np.asarray(clip.object_quat_xyzw, dtype=np.float64)
    points_local = np.asarray(clip.object.sample_points, dtype=np.float64)
    local_distance = getattr(clip.object, "surface_distance", None)
    vertices = getattr(clip.object, "vertices", None)
    hull = None
    if vertices is not None and len(vertices) >= 4:
        hull = (HullPlanes.from_vertices(vertices) if mapping.object_collision == "hull"
                else HullPlanes.from_pieces(clip.object.collision_pieces(mapping.object_collision)))
    labels = getattr(clip, "body_contact", None)
    labels = None if labels is None else np.asarray(labels)[:, human_idx]
    human_pos = body_pos[:, human_idx]
    if mapping.hand_size_fit and hand_length:
        human_pos = fit_hand_size(body_pos, human_pos, list(link_map.values()), hand_length)

    groups = [link_group(h) for h in link_map.values()]
    pos, a, obj_robot, dist = map_positions(
        human_pos, body_pos[:, 0, :2], obj_pos, obj_quat_xyzw, points_local, scale, mapping, labels, local_distance,
        hull)
    base_w = np.array([mapping.group_weights[g] for g in groups])
    weight = base_w[None, :] + mapping.anchor_weight * a
    pin_feet(pos, weight, [i for i, g in enumerate(groups) if g == "feet"], float(clip.fps), mapping)
    return RobotTargets(
        fps=float(clip.fps),
        link_names=tuple(link_map.keys()),
        human_names=tuple(link_map.values()),
        pos=pos,
        weight=weight,
        anchor=a,
        object_pos=obj_robot,
        object_quat_wxyz=xyzw_to_wxyz(obj_quat_xyzw),
        root_quat_wxyz=xyzw_to_wxyz(np.asarray(clip.body_quat_xyzw, dtype=np.float64)[:, 0]),
        scale=float(scale),
        human_pos=human_pos,
        human_surface_dist=dist,
        human_object_pos=obj_pos,
        object_points_local=points_local,
        object_local_distance=local_distance,
        object_hull=hull,
        object_mass_kg=None if clip.object is None else clip.object.mass_kg,
    )

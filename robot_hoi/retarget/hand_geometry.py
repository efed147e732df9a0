"""A robot hand in its wrist link's frame, for placing it on an object (grasp.py).

Built once from the MuJoCo model by forward kinematics with the thumb laid open (its channels at their open
angles) and the other fingers at a table of closures: where the mapped hand links (wrist, fingertips) and the
hand's collision probe spheres (object_contact.hand_probe_points) are, the finger axis, the palm normal (the side
the fingers curl toward), the palm centre and the thumb side. The fingers close through the embodiment's
couplings (kinematics.apply_joint_couplings): one closure drives every finger channel, the mimic joints follow.

On the G1 with Inspire hands the open thumb stands ~1 cm proud of the palm (`reach` 3.3-4.2 cm against the
palm's own 2.1 cm), and the wrist and forearm capsules (radius 2.8 and 3 cm) are thicker than the palm is deep:
a flat palm cannot lie on a large face, which is why grasp.py holds faces with curled fingers.

Each finger is a chain of its own, so one table serves closures per channel too (`at` with a (6,) closure): a
probe or link moves with the one channel it hangs from (`probe_channel`, `link_channel`). The Inspire fingers
differ in length (the middle one reaches furthest), so one closure for all lays a single pad on a flat face;
`finger_closures` closes each finger until its own pad arrives.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.retarget.faces import Face
from robot_hoi.retarget.kinematics import (
    apply_joint_couplings,
    default_qpos,
    joint_ids,
    link_positions,
    resolve_links,
)
from robot_hoi.retarget.object_contact import HullPlanes, hand_probe_points
from robot_hoi.retarget.targets import hand_side, link_group


@dataclass(frozen=True)
class HandGeometry:
    """One hand, wrist-link frame; tables over `closures` (stroke fractions of the non-thumb fingers)."""

    side: str
    links: tuple[str, ...]       # the mapped hand links (wrist first), as in the targets
    closures: np.ndarray         # (C,)
    link_local: np.ndarray       # (C, K, 3)
    probe_local: np.ndarray      # (C, N, 3)
    probe_radius: np.ndarray     # (N,)
    finger: np.ndarray           # (N,) bool: the probe moves with the closure
    axis: np.ndarray             # (3,) from the wrist toward the fingers
    palm_normal: np.ndarray      # (3,) the side the fingers curl toward
    thumb: np.ndarray            # (3,) across the palm toward the thumb
    palm_centre: np.ndarray      # (3,) the palm's largest probe sphere
    reach: float                 # how far the non-finger probes (palm, open thumb) reach along palm_normal
    open_rad: np.ndarray         # (6,) channel angles: fingers open, thumb laid open
    closed_rad: np.ndarray       # (6,) fingers closed, thumb laid open
    probe_channel: np.ndarray    # (N,) the channel a probe moves with, -1 for none (palm, wrist, open thumb)
    link_channel: np.ndarray     # (K,) the same for the links

    def channel_angles(self, closure) -> np.ndarray:
        """(6,) channel angles at a closure: one stroke fraction for every finger, or one per channel (6,)."""
        return self.open_rad + np.asarray(closure, dtype=np.float64) * (self.closed_rad - self.open_rad)

    def at(self, closure) -> tuple[np.ndarray, np.ndarray]:
        """(link positions (K, 3), probe positions (N, 3)) at a closure (a stroke fraction, or one per channel
        (6,)), interpolated between the table's rows."""
        per_channel = np.broadcast_to(np.asarray(closure, dtype=np.float64), (6,))
        return (self._interpolate(self.link_local, per_channel, self.link_channel),
                self._interpolate(self.probe_local, per_channel, self.probe_channel))

    def _interpolate(self, table: np.ndarray, per_channel: np.ndarray, channel: np.ndarray) -> np.ndarray:
        c = np.clip(np.where(channel >= 0, per_channel[channel], 0.0), self.closures[0], self.closures[-1])
        i = np.minimum(np.searchsorted(self.closures, c, side="right") - 1, len(self.closures) - 2)
        s = ((c - self.closures[i]) / (self.closures[i + 1] - self.closures[i]))[:, None]
        rows = np.arange(table.shape[1])
        return (1 - s) * table[i, rows] + s * table[i + 1, rows]

    def finger_closures(self, rotation: np.ndarray, wrist: np.ndarray, planes: HullPlanes, start: float,
                        most: float, clearance: float = 0.0) -> np.ndarray:
        """(6,) per channel: from `start`, the closure at which each finger of the hand at (`rotation`, `wrist`,
        object frame) first comes within `clearance` of the object (its convex `planes`); a finger that does not
        by `most` keeps the closure where it came nearest. Non-finger channels get `start`."""
        grid = np.concatenate([[start], self.closures[(self.closures > start) & (self.closures < most)], [most]])
        gaps = np.array([self._channel_gaps(g, rotation, wrist, planes) for g in grid])  # (G, 6)
        out = np.full(6, float(start))
        for k in np.unique(self.probe_channel[self.probe_channel >= 0]):
            hit = np.flatnonzero(gaps[:, k] <= clearance)
            if not len(hit):
                out[k] = grid[int(np.argmin(gaps[:, k]))]
                continue
            if hit[0] == 0:
                continue
            lo, hi = float(grid[hit[0] - 1]), float(grid[hit[0]])
            for _ in range(6):  # bisect to ~1e-3 of the stroke
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if self._channel_gaps(mid, rotation, wrist, planes)[k] <= clearance else (mid, hi)
            out[k] = hi
        return out

    def _channel_gaps(self, closure: float, rotation, wrist, planes: HullPlanes) -> np.ndarray:
        """(6,) each channel's nearest probe surface to the object at one closure (inf for channels without)."""
        world = self.at(closure)[1] @ rotation.T + wrist
        gap = planes.signed_distance(world)[0] - self.probe_radius
        out = np.full(6, np.inf)
        for k in range(6):
            mine = self.probe_channel == k
            if mine.any():
                out[k] = gap[mine].min()
        return out

    def sink(self, rotation: np.ndarray, wrist: np.ndarray, planes: HullPlanes, closure: float) -> float:
        """How deep (m, >= 0) the hand's probe spheres at `closure` sink into the object."""
        world = self.at(closure)[1] @ rotation.T + wrist
        return float(max((self.probe_radius - planes.signed_distance(world)[0]).max(), 0.0))


def hand_geometry(model: mujoco.MjModel, cfg, side: str, link_names, human_names,
                  closures: np.ndarray | None = None) -> HandGeometry:
    """HandGeometry of one side of an embodiment (`cfg.hands[side]`) for the targets' hand links."""
    closures = np.linspace(0.0, 1.0, 21) if closures is None else np.asarray(closures, dtype=np.float64)
    pairs = list(zip(link_names, human_names, strict=True))
    wrist = next(r for r, h in pairs if hand_side(h) == side and link_group(h) == "wrists")
    links = [wrist] + [r for r, h in pairs if hand_side(h) == side and r != wrist]
    channels = cfg.hands[side].channels
    fingers = np.array([not c.name.startswith("thumb") for c in channels])
    open_rad = np.array([c.open_rad for c in channels], dtype=np.float64)
    closed_rad = np.where(fingers, [c.closed_rad for c in channels], open_rad)
    qadr = model.jnt_qposadr[joint_ids(model, [c.joint for c in channels])]
    wrist_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, wrist)
    probes = hand_probe_points(model, [wrist_id])
    resolved = resolve_links(model, links)
    data, q0 = mujoco.MjData(model), default_qpos(model, cfg)

    def pose(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(links (K, 3), probes (N, 3)) in the wrist link's frame with the hand's channels at `angles`."""
        q = q0.copy()
        q[qadr] = angles
        apply_joint_couplings(model, q)
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        rot, origin = data.xmat[wrist_id].reshape(3, 3), data.xpos[wrist_id]
        world = data.xpos[probes.body_ids] + np.einsum("nij,nj->ni", data.xmat[probes.body_ids].reshape(-1, 3, 3),
                                                       probes.local)
        return (link_positions(data, resolved) - origin) @ rot, (world - origin) @ rot

    tables = [pose(open_rad + c * (closed_rad - open_rad)) for c in closures]
    link_local, probe_local = np.array([t[0] for t in tables]), np.array([t[1] for t in tables])
    # which channel moves each link and probe (-1: none), found by closing one channel at a time
    open_links, open_probes = pose(open_rad)
    link_channel, probe_channel = np.full(len(open_links), -1), np.full(len(open_probes), -1)
    for k in np.flatnonzero(closed_rad != open_rad):
        angles = open_rad.copy()
        angles[k] = closed_rad[k]
        links_k, probes_k = pose(angles)
        link_channel[np.linalg.norm(links_k - open_links, axis=-1) > 1e-6] = k
        probe_channel[np.linalg.norm(probes_k - open_probes, axis=-1) > 1e-6] = k
    moves = probe_channel >= 0
    axis = _unit(probe_local[0][moves].mean(0))
    curl = (probe_local[len(closures) // 3] - probe_local[0])[moves].mean(0)
    normal = _unit(curl - (curl @ axis) * axis)
    rest = np.flatnonzero(~moves)
    palm = rest[int(np.argmax(probes.radius[rest]))]
    across = np.cross(axis, normal)
    on_thumb = rest[probes.body_ids[rest] != probes.body_ids[palm]]
    thumb = across if (probe_local[0][on_thumb] @ across).mean() >= 0 else -across
    reach = float((probe_local[0][rest] @ normal + probes.radius[rest]).max())
    return HandGeometry(side, tuple(links), closures, link_local, probe_local, probes.radius, moves, axis, normal,
                        thumb, probe_local[0][palm], reach, open_rad, closed_rad, probe_channel, link_channel)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def hand_rotation(geometry: HandGeometry, into: np.ndarray, thumb: np.ndarray) -> np.ndarray:
    """(3, 3) wrist orientation whose palm normal is `into` and whose thumb side is `thumb` (made orthogonal)."""
    thumb = _unit(thumb - (thumb @ into) * into)
    target = np.stack([into, thumb, np.cross(into, thumb)], axis=1)
    local = np.stack([geometry.palm_normal, geometry.thumb, np.cross(geometry.palm_normal, geometry.thumb)], axis=1)
    return target @ local.T


def finger_rotation(geometry: HandGeometry, face: Face, fingers: np.ndarray) -> np.ndarray:
    """(3, 3) the palm into `face`, the fingers along `fingers` (in the face's plane)."""
    handed = np.sign(np.cross(geometry.palm_normal, geometry.thumb) @ geometry.axis)  # axis = handed n x thumb
    return hand_rotation(geometry, -face.normal, handed * np.cross(fingers, -face.normal))


def fitted_rotation(geometry: HandGeometry, links: np.ndarray) -> np.ndarray:
    """(3, 3) the orientation of the open hand that best fits hand link positions `links` (K, 3) (the human's
    hand as the targets place it; Kabsch with the centroids matched)."""
    model = geometry.link_local[0][: len(links)]
    u, _, vt = np.linalg.svd((links - links.mean(0)).T @ (model - model.mean(0)))
    return u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt


def turn_palm(geometry: HandGeometry, rotation: np.ndarray, into: np.ndarray) -> np.ndarray:
    """`rotation` turned by the least rotation that points its palm normal along `into`."""
    normal = rotation @ geometry.palm_normal
    axis = np.cross(normal, into)
    sin, cos = float(np.linalg.norm(axis)), float(normal @ into)
    if sin < 1e-9:
        return rotation if cos > 0 else hand_rotation(geometry, into, rotation @ geometry.thumb)
    return Rotation.from_rotvec(axis / sin * np.arctan2(sin, cos)).as_matrix() @ rotation


def place_hand(geometry: HandGeometry, face: Face, point: np.ndarray, rotation: np.ndarray,
               depth: float) -> np.ndarray:
    """The wrist position that puts the palm centre over `point` on `face`, the hand (oriented by `rotation`)
    reaching `depth` past the wrist toward the face touching it."""
    centre = geometry.palm_centre - (geometry.palm_centre @ geometry.palm_normal) * geometry.palm_normal
    return point + face.normal * depth - rotation @ centre

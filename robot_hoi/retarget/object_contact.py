"""Keeping hands out of the object: its collision shape (convex hull or convex pieces) and hand probe points.

The simulation collides with the object's convex hull or its convex pieces (robot_hoi.sim.scene), and the mocap
hands often sink into the object (OMOMO fingertip joints sit 2-5 cm inside the box), so a reference state copied
from them would start an episode with the fingers inside it. Two fixes use the pieces' face planes
(n . x + d <= 0 inside, n outward): anchored targets are pushed out to a clearance (targets.py) and the IK pushes
hand probe points out (ik.py). For a point inside a convex piece, max_k(n_k . x + d_k) is its exact signed distance;
outside it is a lower bound; over several pieces the smallest counts.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import mujoco
import numpy as np
from scipy.spatial import ConvexHull


@dataclass(frozen=True)
class HullPlanes:
    """Face planes of the convex shape(s) the simulation collides with, in the object frame: outward unit normals
    (K, 3) and offsets (K,), piece by piece (piece i's planes start at row piece_starts[i]; one hull is one piece).
    A point's signed distance is its smallest over the pieces."""

    normals: np.ndarray
    offsets: np.ndarray
    piece_starts: tuple[int, ...] = (0,)

    @classmethod
    def from_vertices(cls, vertices: np.ndarray) -> HullPlanes:
        return cls.from_pieces([vertices])

    @classmethod
    def from_pieces(cls, pieces: list[np.ndarray]) -> HullPlanes:
        eqs = [ConvexHull(np.asarray(v, dtype=np.float64)).equations for v in pieces]
        starts = tuple(int(s) for s in np.cumsum([0] + [len(eq) for eq in eqs[:-1]]))
        eq = np.concatenate(eqs)
        return cls(normals=eq[:, :3].copy(), offsets=eq[:, 3].copy(), piece_starts=starts)

    def signed_distance(self, points: np.ndarray, within: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(..., 3) object-frame points -> (signed distance (...), index of the closest face plane (...)).

        `within` (m): the broad phase, for callers that only ask which points are closer than that. Each piece's
        outline (its planes facing the 26 directions of a cube's faces, edges and corners) bounds its distance from
        below; only points whose bound is below `within` are measured against every plane. So the result is exact
        where the distance is below `within`, and elsewhere a lower bound of it that is itself >= `within`."""
        points = np.asarray(points, dtype=np.float64)
        if within is None:
            return self._nearest(points, self._planes)
        dist, face = self._nearest(points, self._outline)
        near = dist < within
        if near.any():
            dist[near], face[near] = self._nearest(points[near], self._planes)
        return dist, face

    def plane_values(self, points: np.ndarray) -> np.ndarray:
        """(..., K) n . x + d of each point and plane."""
        return _plane_values(np.asarray(points, dtype=np.float64), self._planes)

    @cached_property
    def _planes(self) -> _PlaneSet:
        return _PlaneSet.of(self, np.arange(len(self.normals)))

    @cached_property
    def _outline(self) -> _PlaneSet:
        """Per piece, the planes facing the 26 directions of a 3x3x3 grid (max n . direction)."""
        grid = np.array([(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if x or y or z], float)
        stops = self.piece_starts[1:] + (len(self.normals),)
        keep = [np.unique(start + (self.normals[start:stop] @ grid.T).argmax(axis=0))
                for start, stop in zip(self.piece_starts, stops, strict=True)]
        return _PlaneSet.of(self, np.concatenate(keep))

    def _nearest(self, points: np.ndarray, planes: _PlaneSet) -> tuple[np.ndarray, np.ndarray]:
        """Distance and face over a set of planes: each piece's nearest face (max), then the nearest piece (min)."""
        values = _plane_values(points, planes)
        per_piece = np.maximum.reduceat(values, planes.starts, axis=-1)
        piece = per_piece.argmin(axis=-1)  # the first of equals
        dist = np.take_along_axis(per_piece, piece[..., None], axis=-1)[..., 0]
        stops = np.append(planes.starts[1:], len(planes.index))
        face = np.empty(piece.shape, dtype=np.int64)
        for k in np.unique(piece):
            rows = piece == k
            face[rows] = values[rows, planes.starts[k]:stops[k]].argmax(axis=-1) + planes.starts[k]
        return dist, planes.index[face]

    def push_out(self, points: np.ndarray, clearance: float) -> np.ndarray:
        """Points closer than `clearance` to the shape (or inside it) moved out along the nearest face normal
        (of the nearest piece; a second pass for a point pushed into a neighbouring piece)."""
        for _ in range(1 if len(self.piece_starts) == 1 else 2):
            dist, face = self.signed_distance(points, within=clearance)
            gap = np.maximum(clearance - dist, 0.0)
            points = points + gap[..., None] * self.normals[face]
        return points


@dataclass(frozen=True)
class _PlaneSet:
    """Some of a HullPlanes' planes, piece by piece: normals as three contiguous columns, offsets, where each
    piece starts, and each plane's row in the HullPlanes."""

    columns: np.ndarray  # (3, M)
    offsets: np.ndarray  # (M,)
    starts: np.ndarray  # (pieces,)
    index: np.ndarray  # (M,)

    @classmethod
    def of(cls, planes: HullPlanes, index: np.ndarray) -> _PlaneSet:
        piece = np.searchsorted(planes.piece_starts, index, side="right") - 1  # index is sorted, every piece in it
        return cls(np.ascontiguousarray(planes.normals[index].T), planes.offsets[index],
                   np.searchsorted(piece, np.arange(len(planes.piece_starts))), index)


def _plane_values(points: np.ndarray, planes: _PlaneSet) -> np.ndarray:
    """(..., M) n . x + d, one outer product per axis: a BLAS matrix product (points @ normals.T) of this size ran
    10-60x slower when its threads had to share the CPU (a training beside the retarget), and this is the
    retarget's innermost product."""
    nx, ny, nz = planes.columns
    values = np.multiply.outer(points[..., 0], nx)
    values += np.multiply.outer(points[..., 1], ny)
    values += np.multiply.outer(points[..., 2], nz)
    values += planes.offsets
    return values


@dataclass(frozen=True)
class ProbePoints:
    """Points on robot bodies that must stay `radius` away from the object (sphere-swept hand and arm geometry)."""

    body_ids: np.ndarray  # (N,)
    local: np.ndarray  # (N, 3) in the body frame
    radius: np.ndarray  # (N,)
    hand: np.ndarray  # (N,) bool: on a hand (else on an arm)

    def __len__(self) -> int:
        return len(self.body_ids)


def subtree(model, root: int) -> list[int]:
    """Body `root` and every body below it."""
    out = []
    for b in range(model.nbody):
        a = b
        while a > 0 and a != root:
            a = int(model.body_parentid[a])
        if a == root:
            out.append(b)
    return out


def hand_probe_points(model, root_bodies, arm_roots=()) -> ProbePoints:
    """Probe points of the collision geoms in the subtrees of `root_bodies` (e.g. the wrist-yaw links), and of
    `arm_roots` (e.g. the upper arms; their points outside the hands' subtrees have `hand` False).

    Capsules give their two end centres and radius, spheres their centre, boxes their 8 corners (radius 0) and
    centre (radius = smallest half size). Geom frames are fixed in their body, so the points are too.
    """
    hand_bodies = [b for root in root_bodies for b in subtree(model, int(root))]
    arm_bodies = [b for root in arm_roots for b in subtree(model, int(root)) if b not in hand_bodies]
    bodies, local, radius = [], [], []
    for body in hand_bodies + arm_bodies:
        for g in np.flatnonzero(model.geom_bodyid == body):
            if not (model.geom_contype[g] or model.geom_conaffinity[g]):
                continue
            mat = np.zeros(9)
            mujoco.mju_quat2Mat(mat, model.geom_quat[g])
            rot, pos, size = mat.reshape(3, 3), model.geom_pos[g], model.geom_size[g]
            gtype = model.geom_type[g]
            if gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
                pts = [pos + rot[:, 2] * size[1], pos - rot[:, 2] * size[1]]
                rads = [size[0]] * 2
            elif gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
                pts, rads = [pos], [size[0]]
            elif gtype == mujoco.mjtGeom.mjGEOM_BOX:
                signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
                pts = list(pos + (signs * size[:3]) @ rot.T) + [pos]
                rads = [0.0] * 8 + [float(size[:3].min())]
            else:
                continue
            bodies.extend([body] * len(pts))
            local.extend(pts)
            radius.extend(rads)
    bodies = np.asarray(bodies, dtype=np.int64)
    return ProbePoints(bodies, np.asarray(local, dtype=np.float64).reshape(-1, 3), np.asarray(radius, dtype=np.float64),
                       np.isin(bodies, hand_bodies))

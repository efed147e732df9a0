"""The flat sides of an object's collision shape, where a robot hand can be placed (grasp.py).

The simulation collides with the object's convex pieces (object_contact.HullPlanes). A side of a piece is a group
of its hull facets whose normals lie within a few degrees of each other (scanned meshes are not flat), taken at
the piece's supporting plane along the group's area-weighted normal. Sides too small for a palm, and the cuts
between pieces, are left out; sides of two pieces that continue each other (a box the decomposition cut in two)
are merged. Everything is in the object frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

from robot_hoi.retarget.object_contact import HullPlanes


@dataclass(frozen=True)
class Face:
    """A flat side of one convex piece: outward unit normal, plane n.x + offset = 0, its corner points (in the
    plane) and their centroid."""

    piece: int
    normal: np.ndarray
    offset: float
    corners: np.ndarray
    centre: np.ndarray

    def basis(self) -> np.ndarray:
        """(2, 3) orthonormal tangent axes of the face plane."""
        seed = np.eye(3)[int(np.argmin(np.abs(self.normal)))]
        u = np.cross(self.normal, seed)
        u /= np.linalg.norm(u)
        return np.stack([u, np.cross(self.normal, u)])

    def clamp(self, point: np.ndarray, margin: float) -> np.ndarray:
        """`point` projected onto the plane and, where it lies outside the face polygon shrunk by `margin`, moved
        toward the centroid until it is inside (onto the centroid where the face is narrower than 2 margin)."""
        point = point - (self.normal @ point + self.offset) * self.normal
        axes = self.basis()
        xy = (point - self.centre) @ axes.T
        try:
            edges = ConvexHull((self.corners - self.centre) @ axes.T).equations  # n.xy + d <= 0 inside
        except QhullError:
            return self.centre.copy()
        rate = edges[:, :2] @ xy
        room = np.maximum(-margin - edges[:, 2], 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            limits = np.where(rate > 0, room / rate, np.inf)
        return self.centre + min(1.0, float(limits.min())) * xy @ axes

    def extent(self, direction: np.ndarray, point: np.ndarray) -> tuple[float, float]:
        """(lowest, highest) of the corners along `direction`, measured from `point`."""
        along = (self.corners - point) @ direction
        return float(along.min()), float(along.max())


def face_area(face: Face) -> float:
    """Area (m^2) of the face's polygon."""
    try:
        return float(ConvexHull((face.corners - face.centre) @ face.basis().T).volume)
    except QhullError:
        return 0.0


def face_distance(point: np.ndarray, face: Face) -> float:
    """Distance from a point to the face (its polygon)."""
    return float(np.linalg.norm(point - face.clamp(point, 0.0)))


def object_faces(pieces: list[np.ndarray], min_area: float = 0.02, min_width: float = 0.05,
                 max_angle_deg: float = 12.0, depth: float = 0.015) -> list[Face]:
    """The sides of the convex pieces (vertices each): facets within `max_angle_deg` of each other grouped, each
    group's corners the piece's vertices within `depth` of its supporting plane. Sides of at least `min_area` m^2
    and `min_width` across (bevels and rounded edges give no room for a palm); a side whose centre lies inside
    another piece is a cut between pieces and left out."""
    planes = HullPlanes.from_pieces(pieces)
    cos_tol = float(np.cos(np.radians(max_angle_deg)))
    faces = []
    for k, vertices in enumerate(pieces):
        try:
            hull = ConvexHull(np.asarray(vertices, dtype=np.float64))
        except QhullError:
            continue
        for normal in _side_normals(hull, cos_tol):
            face = _side(k, hull.points, normal, depth)
            if face_area(face) > 0 and planes.signed_distance(face.centre + 0.01 * normal)[0] > 0:
                faces.append(face)
    return [f for f in merge_coplanar(faces, cos_tol, depth) if face_area(f) >= min_area and face_width(f) >= min_width]


def face_width(face: Face) -> float:
    """The face's narrowest extent (along its polygon's minor principal axis), m."""
    flat = (face.corners - face.centre) @ face.basis().T
    return float(np.ptp(flat @ np.linalg.svd(flat - flat.mean(0), full_matrices=False)[2].T, axis=0).min())


def _side_normals(hull: ConvexHull, cos_tol: float) -> list[np.ndarray]:
    """Unit normals of the facet groups of a hull: largest facets first, each facet joining the first group whose
    area-weighted normal lies within the tolerance."""
    tri = hull.points[hull.simplices]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    sums: list[np.ndarray] = []
    for i in np.argsort(-area):
        n = hull.equations[i, :3]
        for total in sums:
            if total @ n > cos_tol * np.linalg.norm(total):
                total += area[i] * n
                break
        else:
            sums.append(area[i] * n)
    return [total / np.linalg.norm(total) for total in sums]


def _side(piece: int, points: np.ndarray, normal: np.ndarray, depth: float) -> Face:
    """The side of a piece (its hull's `points`) at its supporting plane along `normal`."""
    height = points @ normal
    offset = -float(height.max())
    near = points[height + offset > -depth]
    corners = near - (near @ normal + offset)[:, None] * normal
    return Face(piece, normal, offset, corners, corners.mean(0))


def merge_coplanar(faces: list[Face], cos_tol: float, depth: float, touch: float = 0.02) -> list[Face]:
    """Faces that lie in one plane, touch, and together make a convex polygon (a side cut in two by the
    decomposition, not a tabletop's edge and the leg below it) merged into one."""
    out: list[Face] = []
    for face in sorted(faces, key=lambda f: -face_area(f)):
        for k, kept in enumerate(out):
            if (kept.normal @ face.normal > cos_tol and abs(kept.normal @ face.centre + kept.offset) < depth
                    and min(face_distance(c, kept) for c in face.corners) < touch):
                corners = np.vstack([kept.corners, face.corners])
                corners -= (corners @ kept.normal + kept.offset)[:, None] * kept.normal
                merged = Face(kept.piece, kept.normal, kept.offset, corners, corners.mean(0))
                if face_area(merged) <= 1.15 * (face_area(kept) + face_area(face)):
                    out[k] = merged
                    break
        else:
            out.append(face)
    return out


def centre_of_mass(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Where the simulation puts the object's mass: the centroid of its solid convex hull (sim/scene.add_object)."""
    return np.asarray(_solid_hull(vertices, faces).center_mass)


def hull_mass(vertices: np.ndarray, faces: np.ndarray, density: float) -> float:
    """kg: the simulated object's mass at `density` (its solid convex hull's, as sim/scene.add_object)."""
    return float(density * _solid_hull(vertices, faces).volume)


def _solid_hull(vertices: np.ndarray, faces: np.ndarray):
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=True).convex_hull

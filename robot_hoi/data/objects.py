"""Object assets of HOI clips: mesh + surface samples in the object-local frame, loaded without pickle.

Layout on disk (InterMimic's): `<objects_dir>/<name>/<name>.obj` (metres, object-local frame, not necessarily
z-up) and `<objects_dir>/<name>/sample_points.npy` (float (N, 3) surface samples in the same frame).
A clip's object pose maps local points to world: world = R(quat_xyzw).apply(p_local) + pos.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from robot_hoi.errors import DataError

DEFAULT_NUM_SAMPLE_POINTS = 340  # what InterMimic ships per object
DENSE_SAMPLES = 6000  # for distance queries: ~1.5 cm spacing on a 0.5 m box
SAMPLE_SEED = 0


@dataclass(eq=False)
class ObjectAsset:
    """A rigid object: triangle mesh and surface samples in its local frame (metres)."""

    name: str
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64
    sample_points: np.ndarray  # (N, 3) float64 surface samples
    mesh_file: str | None = None  # where the mesh came from (None: procedural)
    mass_kg: float | None = None  # None: use a density (InterMimic: 200 kg/m^3)
    _tree: cKDTree | None = field(default=None, init=False, repr=False)
    _hull: np.ndarray | None = field(default=None, init=False, repr=False)

    @property
    def extents(self) -> np.ndarray:
        """Axis-aligned size (3,) of the mesh in its local frame."""
        return self.vertices.max(axis=0) - self.vertices.min(axis=0)

    def to_trimesh(self):
        import trimesh

        return trimesh.Trimesh(vertices=self.vertices, faces=self.faces, process=False)

    def hull_vertices(self) -> np.ndarray:
        """Convex-hull vertices (local): enough to find the lowest point of the object in any pose."""
        if self._hull is None:
            self._hull = np.array(self.to_trimesh().convex_hull.vertices, dtype=np.float64)
        return self._hull

    def surface_distance(self, points_local: np.ndarray) -> np.ndarray:
        """Unsigned distance (m) from local points (..., 3) to the object surface (dense samples, ~1 cm)."""
        if self._tree is None:
            import trimesh

            dense, _ = trimesh.sample.sample_surface(self.to_trimesh(), DENSE_SAMPLES, seed=SAMPLE_SEED)
            self._tree = cKDTree(np.concatenate([np.asarray(dense), self.sample_points, self.vertices]))
        points_local = np.asarray(points_local, dtype=np.float64)
        dist, _ = self._tree.query(points_local.reshape(-1, 3))
        return dist.reshape(points_local.shape[:-1])


def to_world(points_local: np.ndarray, pos: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """Local points (N, 3) in every pose (T,) -> world points (T, N, 3)."""
    rot = Rotation.from_quat(quat_xyzw)
    mats = rot.as_matrix()
    return np.einsum("tij,nj->tni", mats, points_local) + np.asarray(pos)[:, None, :]


def to_local(points_world: np.ndarray, pos: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """World points (T, N, 3) -> object-local points (T, N, 3) for poses (T,)."""
    mats = Rotation.from_quat(quat_xyzw).as_matrix()
    return np.einsum("tji,tnj->tni", mats, points_world - np.asarray(pos)[:, None, :])


def default_objects_dir(clip_path: Path) -> Path:
    """InterMimic's layout: clips/ and objects/ side by side."""
    return clip_path.resolve().parent.parent / "objects"


def _check_points(points: np.ndarray, path: Path) -> np.ndarray:
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 1:
        raise DataError(f"{path}: sample points must be an (N, 3) array, got shape {points.shape}")
    if not np.issubdtype(points.dtype, np.number):
        raise DataError(f"{path}: sample points must be numeric, got dtype {points.dtype}")
    points = points.astype(np.float64)
    if not np.isfinite(points).all():
        raise DataError(f"{path}: sample points contain NaN or inf")
    return points


def load_object_asset(
    name: str, objects_dir: str | Path, *, for_file: str | Path
) -> tuple[ObjectAsset, list[str]]:
    """Load `<objects_dir>/<name>/<name>.obj` and its `sample_points.npy`.

    `for_file` is the clip that needs the object (named in errors). Returns the asset and notes about it (e.g.
    sample points generated because the file is missing).
    """
    import trimesh

    folder = Path(objects_dir) / name
    mesh_path = folder / f"{name}.obj"
    if not mesh_path.is_file():
        raise DataError(
            f"{for_file}: object mesh for '{name}' not found at {mesh_path} "
            "(pass the objects folder, or treat the object as optional)"
        )
    try:
        mesh = trimesh.load(mesh_path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise DataError(f"{for_file}: cannot read object mesh {mesh_path}: {exc}") from exc
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(vertices) < 4 or len(faces) < 4 or not np.isfinite(vertices).all():
        raise DataError(f"{for_file}: object mesh {mesh_path} has no usable triangles")
    notes: list[str] = []
    samples_path = folder / "sample_points.npy"
    if samples_path.is_file():
        try:
            points = np.load(samples_path, allow_pickle=False)
        except Exception as exc:  # ValueError for object arrays, OSError/EOFError for broken files
            raise DataError(f"{for_file}: cannot read sample points {samples_path}: {exc}") from exc
        points = _check_points(points, samples_path)
    else:
        dense, _ = trimesh.sample.sample_surface(mesh, DEFAULT_NUM_SAMPLE_POINTS, seed=SAMPLE_SEED)
        points = np.asarray(dense, dtype=np.float64)
        notes.append(
            f"object '{name}': no sample_points.npy, sampled {len(points)} surface points from the mesh"
        )
    return ObjectAsset(
        name=name, vertices=vertices, faces=faces, sample_points=points, mesh_file=str(mesh_path)
    ), notes


def box_asset(
    size_xyz: tuple[float, float, float], *, name: str = "box", mass_kg: float | None = None, seed: int = 0
) -> ObjectAsset:
    """A procedural box centred on its local origin, with DEFAULT_NUM_SAMPLE_POINTS surface samples."""
    import trimesh

    mesh = trimesh.creation.box(extents=size_xyz)
    points, _ = trimesh.sample.sample_surface(mesh, DEFAULT_NUM_SAMPLE_POINTS, seed=seed)
    return ObjectAsset(
        name=name,
        vertices=np.array(mesh.vertices, dtype=np.float64),
        faces=np.array(mesh.faces, dtype=np.int64),
        sample_points=np.asarray(points, dtype=np.float64),
        mesh_file=None,
        mass_kg=mass_kg,
    )

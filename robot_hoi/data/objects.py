"""Object assets of HOI clips: mesh + surface samples in the object-local frame, loaded without pickle.

Layout on disk (InterMimic's): `<objects_dir>/<name>/<name>.obj` (metres, object-local frame, not necessarily
z-up) and `<objects_dir>/<name>/sample_points.npy` (float (N, 3) surface samples in the same frame).
A clip's object pose maps local points to world: world = R(quat_xyzw).apply(p_local) + pos.
"""

from __future__ import annotations

import hashlib
import zipfile
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from deploy.atomic import atomic_path
from robot_hoi.data.object_urdf import read_mesh, urdf_geometry
from robot_hoi.errors import DataError
from robot_hoi.paths import cache_dir

DEFAULT_NUM_SAMPLE_POINTS = 340  # what InterMimic ships per object
# Convex decomposition (CoACD) of meshes that are not convex (a table's top over its legs, a chair): what the
# simulation collides with when the task asks for object_collision "decomposed". Threshold = CoACD's concavity
# tolerance (fraction of the mesh's size). Coarser search settings than CoACD's defaults (which take 17 s on
# largetable for the same pieces): largetable 6 pieces in 3 s, woodchair 16 in 5 s (idle CPU; 5-8 s and 9-14 s,
# plasticbox 14-20 s, beside a training). Deterministic (seed 0), so each result is kept on disk
# (paths.cache_dir()/convex_parts, by mesh content, these settings and CoACD's version) and made once per machine.
OBJECT_COLLISIONS = ("hull", "decomposed")  # what an object collides as: its convex hull, or its convex pieces
DECOMPOSITION_THRESHOLD = 0.1
DECOMPOSITION_MAX_PARTS = 16
_COACD = {"threshold": DECOMPOSITION_THRESHOLD, "max_convex_hull": DECOMPOSITION_MAX_PARTS,
          "preprocess_resolution": 30, "resolution": 1000, "mcts_iterations": 60, "seed": 0}
_DECOMPOSITIONS: dict[str, list[np.ndarray]] = {}  # by mesh content: envs and the retarget share one decomposition

DENSE_SAMPLES = 6000  # for distance queries: ~1.5 cm spacing on a 0.5 m box
SAMPLE_SEED = 0
BOX_DEFAULT_M = 0.4  # box edge when the clip says nothing about the object's size
BOX_MIN_HALF_M = 0.05


@dataclass(eq=False)
class ObjectAsset:
    """A rigid object: triangle mesh and surface samples in its local frame (metres)."""

    name: str
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64
    sample_points: np.ndarray  # (N, 3) float64 surface samples
    mesh_file: str | None = None  # where the mesh came from (None: procedural)
    mass_kg: float | None = None  # None: use a density (InterMimic: 200 kg/m^3)
    origin: str = "procedural"  # which of the dataset's files the shape came from (one line, for notes)
    _tree: cKDTree | None = field(default=None, init=False, repr=False)
    _hull: np.ndarray | None = field(default=None, init=False, repr=False)

    @property
    def extents(self) -> np.ndarray:
        """Axis-aligned size (3,) of the mesh in its local frame."""
        return self.vertices.max(axis=0) - self.vertices.min(axis=0)

    def to_trimesh(self):
        return trimesh.Trimesh(vertices=self.vertices, faces=self.faces, process=False)

    def hull_vertices(self) -> np.ndarray:
        """Convex-hull vertices (local): enough to find the lowest point of the object in any pose."""
        if self._hull is None:
            self._hull = np.array(self.to_trimesh().convex_hull.vertices, dtype=np.float64)
        return self._hull

    def convex_parts(self) -> list[np.ndarray]:
        """Vertices (local) of convex pieces whose union approximates the mesh (CoACD, deterministic); a convex
        mesh (a box) is one piece, its hull."""
        key = hashlib.sha256(np.ascontiguousarray(self.vertices).tobytes()
                             + np.ascontiguousarray(self.faces).tobytes()).hexdigest()
        if key not in _DECOMPOSITIONS:
            convex = self.to_trimesh().is_convex
            _DECOMPOSITIONS[key] = [self.hull_vertices()] if convex else _stored_decomposition(key, self.vertices,
                                                                                               self.faces)
        return [v.copy() for v in _DECOMPOSITIONS[key]]

    def collision_pieces(self, object_collision: str) -> list[np.ndarray]:
        """Vertices of the convex shapes the object collides as: [its hull] or its convex_parts()."""
        check_object_collision(object_collision)
        return self.convex_parts() if object_collision == "decomposed" else [self.hull_vertices()]

    def surface_distance(self, points_local: np.ndarray) -> np.ndarray:
        """Unsigned distance (m) from local points (..., 3) to the object surface (dense samples, ~1 cm)."""
        if self._tree is None:
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


def check_object_collision(value: str, error: type[Exception] = DataError) -> None:
    """Raise `error` unless `value` names one of OBJECT_COLLISIONS."""
    if value not in OBJECT_COLLISIONS:
        raise error(f"object_collision must be one of {', '.join(OBJECT_COLLISIONS)}, not '{value}'")


def _decompose(vertices: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    # here, not at the top: with coacd's library loaded first, importing onnxruntime segfaults (unless torch
    # came before both; coacd 1.0.14, onnxruntime 1.32)
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)),
                            **_COACD)
    return [np.asarray(v, dtype=np.float64) for v, _ in parts if len(v) >= 4]


def decomposition_file(mesh_key: str) -> Path:
    """Where the decomposition of the mesh with content hash `mesh_key` is kept: named by that hash, the CoACD
    settings and CoACD's version, so a change of any of them makes a new file."""
    recipe = hashlib.sha256(repr((sorted(_COACD.items()), version("coacd"))).encode()).hexdigest()
    return cache_dir() / "convex_parts" / f"{mesh_key[:32]}-{recipe[:12]}.npz"


def _stored_decomposition(mesh_key: str, vertices: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    """The decomposition from its file, else made (CoACD) and written there (atomically; an unwritable cache
    folder only costs the time next run)."""
    path = decomposition_file(mesh_key)
    try:
        with np.load(path, allow_pickle=False) as stored:
            return [stored[f"part{i}"] for i in range(len(stored.files))]
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        pass  # missing, or unreadable: made (again) and written
    parts = _decompose(vertices, faces)
    try:
        with atomic_path(path) as partial:
            np.savez(partial, **{f"part{i}": v for i, v in enumerate(parts)})
    except OSError:
        pass
    return parts


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


def _usable(mesh, where: Path, for_file) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(vertices) < 4 or len(faces) < 4 or not np.isfinite(vertices).all():
        raise DataError(f"{for_file}: object mesh {where} has no usable triangles")
    return vertices, faces


def _read_samples(folder: Path, for_file) -> np.ndarray | None:
    path = folder / "sample_points.npy"
    if not path.is_file():
        return None
    try:
        points = np.load(path, allow_pickle=False)
    except Exception as exc:  # ValueError for object arrays, OSError/EOFError for broken files
        raise DataError(f"{for_file}: cannot read sample points {path}: {exc}") from exc
    return _check_points(points, path)


def load_object_asset(
    name: str, objects_dir: str | Path, *, for_file: str | Path, clip=None
) -> tuple[ObjectAsset, list[str]]:
    """The object from what the dataset ships in `<objects_dir>/<name>/`, best first: `<name>.obj`, the geometry
    of `<name>.urdf`, the convex hull of `sample_points.npy`, else (with `clip`, an HOIClip) a box from the clip.

    `for_file` is the clip that needs the object (named in errors). Returns the asset and notes: the first one
    says which source was used (`ObjectAsset.origin` holds the same line).
    """
    folder = Path(objects_dir) / name
    mesh_path = folder / f"{name}.obj"
    samples = _read_samples(folder, for_file)
    mass = None
    if mesh_path.is_file():
        mesh, origin = read_mesh(mesh_path, for_file), f"mesh {mesh_path}"
    else:
        urdf = folder / f"{name}.urdf"
        mesh, mass, missing = urdf_geometry(urdf, folder, for_file) if urdf.is_file() else (None, None, "")
        if mesh is not None:
            origin = f"geometry of {urdf}"
        elif samples is not None and len(samples) >= 4:
            mesh = trimesh.convex.convex_hull(samples)
            origin = f"convex hull of {folder / 'sample_points.npy'} (no {name}.obj{missing})"
        elif clip is not None:
            asset = box_from_clip(clip, name)
            return asset, [f"object '{name}': {asset.origin}"]
        else:
            raise DataError(
                f"{for_file}: nothing to build object '{name}' from in {folder} (no {name}.obj, {name}.urdf or "
                "sample_points.npy); pass the objects folder with --objects DIR"
            )
    vertices, faces = _usable(mesh, folder, for_file)
    notes = [f"object '{name}': {origin}"]
    if samples is None:
        dense, _ = trimesh.sample.sample_surface(mesh, DEFAULT_NUM_SAMPLE_POINTS, seed=SAMPLE_SEED)
        samples = np.asarray(dense, dtype=np.float64)
        notes.append(
            f"object '{name}': no sample_points.npy, sampled {len(samples)} surface points from the mesh"
        )
    mesh_file = str(mesh_path) if mesh_path.is_file() else None
    return ObjectAsset(name=name, vertices=vertices, faces=faces, sample_points=samples, mesh_file=mesh_file,
                       mass_kg=mass, origin=origin), notes


def box_from_clip(clip, name: str) -> ObjectAsset:
    """A box about the object's origin, just big enough to reach every body point the clip labels as touching
    the object (stored per-body labels) and, along the local axis pointing down in the first frame, the floor
    (the object rests on it there). Without labels: a BOX_DEFAULT_M cube."""
    frames, bodies = np.nonzero(np.asarray(clip.body_contact) > 0)
    if len(frames):
        touching = np.asarray(clip.body_pos)[frames, bodies][:, None]
        local = to_local(touching, np.asarray(clip.object_pos)[frames], np.asarray(clip.object_quat_xyzw)[frames])
        half = np.percentile(np.abs(local[:, 0]), 98, axis=0)  # a few mislabelled frames do not inflate it
    else:
        half = np.full(3, BOX_DEFAULT_M / 2)
    down = Rotation.from_quat(clip.object_quat_xyzw[0]).inv().apply([0.0, 0.0, -1.0])
    axis = int(np.argmax(np.abs(down)))
    half[axis] = max(half[axis], float(clip.object_pos[0, 2]))
    size = 2 * np.maximum(half, BOX_MIN_HALF_M)
    asset = box_asset(tuple(size), name=name)
    how = "contact labels and floor" if len(frames) else f"no contact labels: a {BOX_DEFAULT_M:g} m cube"
    asset.origin = (f"box {size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} m estimated from the clip ({how}); "
                    "no mesh, URDF or sample points found")
    return asset


def box_asset(
    size_xyz: tuple[float, float, float], *, name: str = "box", mass_kg: float | None = None, seed: int = 0
) -> ObjectAsset:
    """A procedural box centred on its local origin, with DEFAULT_NUM_SAMPLE_POINTS surface samples."""
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

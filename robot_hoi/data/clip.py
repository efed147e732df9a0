"""`HOIClip`: one human-object-interaction clip in explicit conventions, and its project-native file format.

Conventions: world z-up, ground at z = 0, metres, radians; every quaternion is xyzw (scipy), named `*_xyzw`.
Body order and parents: `robot_hoi.data.layout.BODY_NAMES` / `BODY_PARENTS` (52 bodies, pelvis first).

Native format: `<stem>.npz` (numeric arrays only; read with allow_pickle=False) next to `<stem>.json`
(name, fps, subject, height, object, license, source, format version, notes). The object mesh and its surface
samples travel inside the npz, so a saved clip is self-contained.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from deploy.atomic import atomic_path, atomic_write_text
from robot_hoi.data.objects import ObjectAsset
from robot_hoi.errors import DataError, UserError

FORMAT_NAME = "robot-hoi-clip"
FORMAT_VERSION = 1

# Per-frame arrays (first axis = time) and their dtypes in memory and on disk.
FRAME_ARRAYS = {
    "root_pos": np.float64,
    "root_quat_xyzw": np.float64,
    "dof_rotvec": np.float64,
    "body_pos": np.float64,
    "body_quat_xyzw": np.float64,
    "object_pos": np.float64,
    "object_quat_xyzw": np.float64,
    "contact": np.int8,  # stored object-contact flag, 0/1
    "body_contact": np.int8,  # stored per-body labels +1 / -1 / 0
    "inferred_contact": np.bool_,  # from object dynamics + distances (robot_hoi.data.contacts)
    "inferred_body_contact": np.int8,  # +1 promote / -1 penalise / 0 neutral
}
FRAME_SHAPES = {
    "root_pos": (3,),
    "root_quat_xyzw": (4,),
    "dof_rotvec": (51, 3),
    "body_pos": (52, 3),
    "body_quat_xyzw": (52, 4),
    "object_pos": (3,),
    "object_quat_xyzw": (4,),
    "contact": (),
    "body_contact": (52,),
    "inferred_contact": (),
    "inferred_body_contact": (52,),
}


@dataclass(eq=False)
class HOIClip:
    name: str
    fps: float
    root_pos: np.ndarray  # (T, 3) pelvis position, world
    root_quat_xyzw: np.ndarray  # (T, 4) pelvis orientation, world
    dof_rotvec: np.ndarray  # (T, 51, 3) joint rotations relative to the parent, bodies 1..51
    body_pos: np.ndarray  # (T, 52, 3) world positions
    body_quat_xyzw: np.ndarray  # (T, 52, 4) global orientations (identity = T-pose facing +x)
    object_pos: np.ndarray  # (T, 3) world position of the object's local origin
    object_quat_xyzw: np.ndarray  # (T, 4) world = R(q).apply(p_local) + object_pos
    contact: np.ndarray  # (T,) int8 stored object-contact flag
    body_contact: np.ndarray  # (T, 52) int8 stored labels +1 touching / -1 far / 0 undetermined
    inferred_contact: np.ndarray  # (T,) bool, inferred from object dynamics and distances
    inferred_body_contact: np.ndarray  # (T, 52) int8, +1 / -1 / 0 like the stored labels
    object_name: str
    object: ObjectAsset | None = None
    subject: str | None = None
    subject_height_m: float | None = None
    height_source: str = "unknown"  # "table" (SOURCES.md), "estimated" (skeleton), "synthetic", "unknown"
    source: str = ""
    license: str = ""
    problems: list[str] = field(default_factory=list)  # what loading found and fixed, for `inspect`

    @property
    def num_frames(self) -> int:
        return int(self.root_pos.shape[0])

    @property
    def duration(self) -> float:
        """Seconds covered by the frames (num_frames / fps, as the dataset tables count)."""
        return self.num_frames / self.fps

    @property
    def times(self) -> np.ndarray:
        return np.arange(self.num_frames) / self.fps

    def frame_arrays(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in FRAME_ARRAYS}

    def select_frames(self, index) -> HOIClip:
        """A new clip holding only the given frames (slice, index array or boolean mask)."""
        arrays = {k: np.array(v[index]) for k, v in self.frame_arrays().items()}
        return replace(self, **arrays, problems=list(self.problems))

    def copy(self) -> HOIClip:
        return self.select_frames(slice(None))

    def save(self, path: str | Path) -> Path:
        """Write `<stem>.npz` + `<stem>.json` atomically. Returns the npz path."""
        path = Path(path)
        if path.suffix != ".npz":
            raise UserError(f"{path}: native clips are saved as .npz (got '{path.suffix or 'no suffix'}')")
        arrays = {k: np.asarray(v, dtype=FRAME_ARRAYS[k]) for k, v in self.frame_arrays().items()}
        if self.object is not None:
            arrays["object_vertices"] = np.asarray(self.object.vertices, dtype=np.float64)
            arrays["object_faces"] = np.asarray(self.object.faces, dtype=np.int64)
            arrays["object_sample_points"] = np.asarray(self.object.sample_points, dtype=np.float64)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:  # a file object: numpy must not append its own ".npz"
                np.savez_compressed(f, **arrays)
        meta = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "name": self.name,
            "fps": float(self.fps),
            "num_frames": self.num_frames,
            "subject": self.subject,
            "subject_height_m": self.subject_height_m,
            "height_source": self.height_source,
            "object_name": self.object_name,
            "object_mesh_file": self.object.mesh_file if self.object is not None else None,
            "object_mass_kg": self.object.mass_kg if self.object is not None else None,
            "source": self.source,
            "license": self.license,
            "quaternion_convention": "xyzw",
            "problems": list(self.problems),
        }
        atomic_write_text(sidecar_path(path), json.dumps(meta, indent=2) + "\n")
        return path


def load_clip(path: str | Path, **kwargs) -> HOIClip:
    """Load a clip: `.pt` (InterMimic, read without unpickling) or `.npz` (native). See `readers.read_clip`."""
    # not at the top: a cycle (readers builds its HOIClips from this module)
    from robot_hoi.data.readers import read_clip

    return read_clip(path, **kwargs)


def sidecar_path(npz_path: str | Path) -> Path:
    npz_path = Path(npz_path)
    return npz_path.with_name(npz_path.stem + ".json")


def read_native_arrays(path: Path) -> tuple[dict[str, np.ndarray], dict]:
    """The npz arrays and the JSON sidecar of a native clip, checked for presence, dtype and shape."""
    meta_path = sidecar_path(path)
    if not meta_path.is_file():
        raise DataError(f"{path}: sidecar {meta_path.name} (fps, names, license) is missing next to the npz")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{meta_path}: not valid JSON ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise DataError(f"{meta_path}: not a {FORMAT_NAME} sidecar")
    if int(meta.get("format_version", -1)) > FORMAT_VERSION:
        raise DataError(f"{meta_path}: format version {meta.get('format_version')} is newer than this reader")
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except FileNotFoundError as exc:
        raise DataError(f"{path}: file not found") from exc
    except Exception as exc:  # zipfile.BadZipFile, ValueError (object arrays), OSError, EOFError
        raise DataError(f"{path}: not a readable npz of numeric arrays ({exc})") from exc
    missing = [k for k in FRAME_ARRAYS if k not in arrays]
    if missing:
        raise DataError(f"{path}: missing arrays {', '.join(missing)}")
    num_frames = arrays["root_pos"].shape[0] if arrays["root_pos"].ndim else 0
    for key, shape in FRAME_SHAPES.items():
        arr = arrays[key]
        if arr.shape != (num_frames, *shape):
            raise DataError(f"{path}: array '{key}' has shape {arr.shape}, expected {(num_frames, *shape)}")
        wants_int = FRAME_ARRAYS[key] in (np.int8, np.bool_)
        kind_ok = arr.dtype.kind in ("i", "u", "b") if wants_int else arr.dtype.kind in ("f", "i", "u")
        if not kind_ok:
            raise DataError(
                f"{path}: array '{key}' has dtype {arr.dtype}, expected {np.dtype(FRAME_ARRAYS[key])}"
            )
        arrays[key] = arr.astype(FRAME_ARRAYS[key], copy=False)
    return arrays, meta

"""The geometry of a single-link object URDF (as InterMimic ships them) as one trimesh, in the link frame.

Collision geometry is preferred over visual; mesh, box, cylinder and sphere elements are read, each placed by its
`<origin xyz rpy>` and mesh `scale`. Mesh file names are resolved like a URDF loader would, relative to the URDF
and to the folders above it (InterMimic writes `objects/<name>/<name>.obj` relative to its assets folder), with
`package://` dropped. `read_mesh` reads one mesh file (objects.py reads an object's `<name>.obj` with it too).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from robot_hoi.errors import DataError


def _floats(text: str | None, count: int, default: float) -> np.ndarray:
    values = [float(v) for v in (text or "").split()] or [default] * count
    return np.array(values if len(values) == count else values[:1] * count, dtype=np.float64)


def read_mesh(path: Path, for_file):
    """A mesh file as one trimesh (`for_file` is named in errors)."""
    try:
        return trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise DataError(f"{for_file}: cannot read object mesh {path}: {exc}") from exc


def _find_mesh(filename: str, urdf: Path, folder: Path) -> Path | None:
    name = filename.removeprefix("package://").removeprefix("file://")
    for base in (urdf.parent, urdf.parent.parent, urdf.parent.parent.parent):
        if (base / name).is_file():
            return base / name
    local = folder / Path(name).name  # the file next to the URDF, whatever folder the URDF names
    return local if local.is_file() else None


def _element_mesh(geometry: ET.Element, urdf: Path, folder: Path):
    """(trimesh or None, missing mesh file name or '')."""
    for shape in geometry:
        if shape.tag == "box":
            return trimesh.creation.box(extents=_floats(shape.get("size"), 3, 0.0)), ""
        if shape.tag == "cylinder":
            return trimesh.creation.cylinder(radius=float(shape.get("radius", 0)),
                                             height=float(shape.get("length", 0))), ""
        if shape.tag == "sphere":
            return trimesh.creation.icosphere(radius=float(shape.get("radius", 0))), ""
        if shape.tag == "mesh":
            path = _find_mesh(shape.get("filename", ""), urdf, folder)
            if path is None:
                return None, shape.get("filename", "")
            mesh = read_mesh(path, urdf).copy()
            mesh.apply_scale(_floats(shape.get("scale"), 3, 1.0))
            return mesh, ""
    return None, ""


def urdf_geometry(urdf: Path, folder: Path, for_file) -> tuple[object | None, float | None, str]:
    """(mesh in the link frame or None, mass in kg from <inertial> or None, a note on a missing mesh file)."""
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError) as exc:
        raise DataError(f"{for_file}: cannot read object URDF {urdf}: {exc}") from exc
    link = root.find("link")
    if link is None:
        return None, None, ""
    mass_el = link.find("inertial/mass")
    mass = float(mass_el.get("value")) if mass_el is not None and mass_el.get("value") else None
    parts, missing = [], []
    for kind in ("collision", "visual"):
        for element in link.findall(kind):
            geometry = element.find("geometry")
            mesh, lost = _element_mesh(geometry, urdf, folder) if geometry is not None else (None, "")
            if lost:
                missing.append(lost)
            if mesh is None:
                continue
            origin = element.find("origin")
            xyz = _floats(origin.get("xyz") if origin is not None else None, 3, 0.0)
            rpy = _floats(origin.get("rpy") if origin is not None else None, 3, 0.0)
            transform = np.eye(4)
            transform[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # URDF: fixed-axis roll, pitch, yaw
            transform[:3, 3] = xyz
            parts.append(mesh.apply_transform(transform))
        if parts:
            break
    note = f"; {urdf.name} names {', '.join(sorted(set(missing)))}, not found" if missing else ""
    return (trimesh.util.concatenate(parts) if parts else None), mass, note

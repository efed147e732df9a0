"""Load clips from disk: InterMimic `.pt` or native `.npz`, validated, repaired where known, with contacts.

Pipeline for a `.pt`: read the tensor without unpickling -> drop placeholder frames -> (optionally) fill NaN
frames -> validate -> quaternion signs -> finger rows -> object asset -> subject height -> inferred contacts ->
soft warnings. Every fix and warning lands in `clip.problems`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robot_hoi.data.clip import FRAME_ARRAYS, HOIClip, read_native_arrays
from robot_hoi.data.contacts import ContactParams, infer_contacts
from robot_hoi.data.intermimic import check_label_values, clip_from_matrix, read_intermimic_matrix
from robot_hoi.data.objects import ObjectAsset, default_objects_dir, load_object_asset
from robot_hoi.data.quirks import fix_quaternion_signs, fix_shifted_finger_rows, leading_placeholder_frames
from robot_hoi.data.resample import fill_frames, fill_missing_frames
from robot_hoi.data.scale import subject_height
from robot_hoi.data.validate import (
    DEFAULT_MIN_DURATION_S,
    clip_warnings,
    rotation_glitch_notes,
    validate_clip,
)
from robot_hoi.errors import DataError, UserError


def read_clip(
    path: str | Path,
    *,
    objects_dir: str | Path | None = None,
    object_optional: bool = False,
    object_name: str | None = None,
    min_duration_s: float | None = DEFAULT_MIN_DURATION_S,
    repair_missing: bool = False,
    contact_params: ContactParams | None = None,
) -> HOIClip:
    """Load `.pt` (InterMimic) or `.npz` (native) and return a validated HOIClip.

    objects_dir: folder with `<object>/` (mesh, URDF or sample points; default: `<clip_dir>/../objects`); when it
    has none of them the object is a box estimated from the clip, unless object_optional: then no object (no
    inferred contacts); repair_missing: interpolate NaN/inf frames
    and one-frame root/object rotation spikes instead of failing; min_duration_s: None disables the length check.
    """
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: file not found")
    kwargs = dict(objects_dir=objects_dir, object_optional=object_optional, object_name=object_name,
                  min_duration_s=min_duration_s, repair_missing=repair_missing, contact_params=contact_params)  # fmt: skip
    if path.suffix == ".pt":
        return read_intermimic_clip(path, **kwargs)
    if path.suffix == ".npz":
        return read_native_clip(path, **kwargs)
    raise UserError(f"{path}: unknown clip format '{path.suffix}' (expected .pt or .npz)")


def _load_object(path: Path, clip: HOIClip, objects_dir, optional: bool) -> tuple[ObjectAsset | None, list[str]]:
    """The clip's object from the dataset's files, else a box from the clip (object_optional: no object)."""
    name = clip.object_name
    if not name:
        if optional:
            return None, ["object unknown (name is not subX_OBJECT_NNN): contacts not inferred"]
        raise DataError(
            f"{path}: cannot tell the object from the file name (expected subX_OBJECT_NNN); name it (--object-name)"
        )
    folder = Path(objects_dir) if objects_dir is not None else default_objects_dir(path)
    try:
        return load_object_asset(name, folder, for_file=path, clip=None if optional else clip)
    except DataError as exc:
        if optional:
            return None, [f"object not loaded ({exc}); contacts not inferred"]
        raise


def _finish(
    clip: HOIClip, path: Path, notes: list[str], *, repair_missing: bool, min_duration_s
) -> list[str]:
    if repair_missing:
        notes += fill_missing_frames(clip)
        notes += _repair_rotation_glitches(clip)
    validate_clip(clip, path=path, min_duration_s=min_duration_s)
    notes += fix_quaternion_signs(clip)
    clip.body_pos, finger_notes = fix_shifted_finger_rows(clip.body_pos, clip.body_quat_xyzw)
    return notes + finger_notes


def _repair_rotation_glitches(clip: HOIClip) -> list[str]:
    """One-frame rotation spikes: the root's frame is re-interpolated whole (every body turns with the root), the
    object's only in its pose."""
    notes = []
    for key, bad, what in rotation_glitch_notes(clip):
        keys = None if key == "root_quat_xyzw" else ("object_pos", "object_quat_xyzw")
        notes += fill_frames(clip, bad, f"where the {what}", keys)
    return notes


def _infer(clip: HOIClip, params: ContactParams | None) -> list[str]:
    if clip.object is None:
        return []
    estimate = infer_contacts(
        clip.body_pos, clip.object, clip.object_pos, clip.object_quat_xyzw, clip.fps, params
    )
    clip.inferred_contact = estimate.contact
    clip.inferred_body_contact = estimate.body_contact
    return estimate.problems


def read_intermimic_clip(path: Path, *, objects_dir, object_optional, object_name, min_duration_s,
                         repair_missing, contact_params) -> HOIClip:  # fmt: skip
    raw = read_intermimic_matrix(path)
    notes: list[str] = []
    placeholder = leading_placeholder_frames(raw)
    if placeholder == len(raw):
        raise DataError(f"{path}: every frame is empty (all kinematic columns are 0)")
    if placeholder:
        raw = raw[placeholder:]
        notes.append(
            f"fixed: dropped {placeholder} placeholder frame(s) at the start (all kinematic columns 0)"
        )
    check_label_values(raw, path)
    clip = clip_from_matrix(raw, name=path.stem)
    if object_name:
        clip.object_name = object_name
    notes = _finish(clip, path, notes, repair_missing=repair_missing, min_duration_s=min_duration_s)
    height = subject_height(clip.subject, clip.body_pos, clip.body_quat_xyzw)
    clip.subject_height_m, clip.height_source = height.height_m, height.source
    if height.source == "estimated":
        notes.append(f"subject height unknown: estimated {height.height_m:.2f} m from the skeleton")
    clip.object, object_notes = _load_object(path, clip, objects_dir, object_optional)
    notes += object_notes + _infer(clip, contact_params)
    clip.problems = notes + clip_warnings(clip)
    return clip


def read_native_clip(path: Path, *, objects_dir, object_optional, object_name, min_duration_s,
                     repair_missing, contact_params) -> HOIClip:  # fmt: skip
    arrays, meta = read_native_arrays(path)
    try:
        fps = float(meta["fps"])
        name = str(meta.get("name") or path.stem)
    except (KeyError, TypeError, ValueError) as exc:
        raise DataError(f"{path}: sidecar lacks a valid 'fps' / 'name' ({exc})") from exc
    obj_name = object_name or str(meta.get("object_name") or "")
    frame_arrays = {k: arrays[k] for k in FRAME_ARRAYS}
    height = meta.get("subject_height_m")
    clip = HOIClip(
        name=name,
        fps=fps,
        **{k: np.array(v) for k, v in frame_arrays.items()},
        object_name=obj_name,
        subject=meta.get("subject"),
        subject_height_m=None if height is None else float(height),
        height_source=str(meta.get("height_source", "unknown")),
        source=str(meta.get("source", "")),
        license=str(meta.get("license", "")),
    )
    notes = _finish(clip, path, list(meta.get("problems") or []), repair_missing=repair_missing,
                    min_duration_s=min_duration_s)  # fmt: skip
    if "object_vertices" in arrays:
        clip.object = _embedded_object(path, arrays, obj_name, meta)
    else:
        clip.object, object_notes = _load_object(path, clip, objects_dir, object_optional)
        notes += object_notes + _infer(clip, contact_params)
    clip.problems = list(dict.fromkeys(notes + clip_warnings(clip)))  # keep order, drop repeats
    return clip


def _embedded_object(path: Path, arrays: dict, name: str, meta: dict) -> ObjectAsset:
    vertices = arrays["object_vertices"]
    faces = arrays.get("object_faces")
    points = arrays.get("object_sample_points")
    if faces is None or points is None:
        raise DataError(
            f"{path}: object arrays incomplete (need object_vertices, object_faces, object_sample_points)"
        )
    for key, arr, cols in (
        ("object_vertices", vertices, 3),
        ("object_faces", faces, 3),
        ("object_sample_points", points, 3),
    ):
        if arr.ndim != 2 or arr.shape[1] != cols or len(arr) == 0 or arr.dtype.kind not in "fiu":
            raise DataError(
                f"{path}: '{key}' must be a non-empty numeric (N, 3) array, got {arr.shape} {arr.dtype}"
            )
        if not np.isfinite(arr).all():
            raise DataError(f"{path}: '{key}' contains NaN or inf")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise DataError(f"{path}: 'object_faces' index vertices that do not exist")
    mass = meta.get("object_mass_kg")
    return ObjectAsset(
        name=name,
        vertices=vertices.astype(np.float64),
        faces=faces.astype(np.int64),
        sample_points=points.astype(np.float64),
        mesh_file=meta.get("object_mesh_file"),
        mass_kg=None if mass is None else float(mass),
    )

"""Clip validation: hard errors (DataError naming the file and the problem) and soft warnings for `inspect`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.data.clip import FRAME_SHAPES, HOIClip
from robot_hoi.data.kinematics import bone_offsets, rotvec_mismatch
from robot_hoi.data.layout import BODY_NAMES
from robot_hoi.data.objects import to_world
from robot_hoi.data.segments import format_segments
from robot_hoi.errors import DataError

DEFAULT_MIN_DURATION_S = 2.0  # 60 frames at 30 fps
QUAT_NORM_TOLERANCE = 1e-3
ROTVEC_TOLERANCE_RAD = 1e-3
ROOT_TOLERANCE_M = 1e-3
BONE_STD_WARN_M = 0.005
FLOOR_WARN_M = -0.05
ROOT_JUMP_WARN_M_S = 5.0
# Fastest turn accepted between two frames: 10 deg at 30 fps. The shared OMOMO clips peak at 213 deg/s (the
# physics-corrected take; 150 deg/s for the mocap), a MoCap glitch of 11.7 deg in one frame is 351 deg/s.
ROT_JUMP_DEG_S = 300.0
ROTATION_STREAMS = {"root_quat_xyzw": "root", "object_quat_xyzw": "object"}

_FLOAT_FIELDS = ("root_pos", "root_quat_xyzw", "dof_rotvec", "body_pos", "body_quat_xyzw", "object_pos",
                 "object_quat_xyzw")  # fmt: skip
_QUAT_FIELDS = ("root_quat_xyzw", "body_quat_xyzw", "object_quat_xyzw")


def nonfinite_frames(clip: HOIClip) -> np.ndarray:
    """(T,) True where any kinematic value of the frame is NaN or inf."""
    bad = np.zeros(clip.num_frames, dtype=bool)
    for key in _FLOAT_FIELDS:
        arr = getattr(clip, key)
        bad |= ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1)
    return bad


def rotation_steps_deg(quat_xyzw: np.ndarray) -> np.ndarray:
    """(T-1,) angle in degrees between consecutive orientations (quaternion sign does not matter)."""
    rot = Rotation.from_quat(quat_xyzw)
    return np.degrees((rot[:-1].inv() * rot[1:]).magnitude())


def rotation_glitches(quat_xyzw: np.ndarray, fps: float) -> np.ndarray:
    """(T,) True at frames that turn away from both neighbours faster than ROT_JUMP_DEG_S while the neighbours
    themselves agree: a one-frame spike, which interpolating the frame repairs safely."""
    limit = ROT_JUMP_DEG_S / fps
    bad = np.zeros(len(quat_xyzw), dtype=bool)
    if len(quat_xyzw) < 3:
        return bad
    step = rotation_steps_deg(quat_xyzw)
    rot = Rotation.from_quat(quat_xyzw)
    across = np.degrees((rot[:-2].inv() * rot[2:]).magnitude())  # frame t-1 to t+1, skipping t
    bad[1:-1] = (step[:-1] > limit) & (step[1:] > limit) & (across < np.minimum(step[:-1], step[1:]) / 2)
    return bad


def rotation_glitch_notes(clip: HOIClip) -> list[tuple[str, np.ndarray, str]]:
    """(field, frames, description) per rotation stream with one-frame spikes."""
    found = []
    for key, label in ROTATION_STREAMS.items():
        bad = rotation_glitches(getattr(clip, key), clip.fps)
        if bad.any():
            worst = float(np.max(rotation_steps_deg(getattr(clip, key))[np.flatnonzero(bad) - 1]))
            found.append((key, bad, f"{label} rotation jumps {worst:.1f} deg for one frame and back "
                                    f"({worst * clip.fps:.0f} deg/s > {ROT_JUMP_DEG_S:g})"))
    return found


def validate_clip(
    clip: HOIClip, *, path: str | Path, min_duration_s: float | None = DEFAULT_MIN_DURATION_S
) -> None:
    """Raise DataError on anything a consumer cannot use: shapes, NaN/inf, non-unit quaternions, labels,
    inconsistent root / joint rotations, too short."""
    if not (np.isfinite(clip.fps) and clip.fps > 0):
        raise DataError(f"{path}: fps must be positive, got {clip.fps}")
    num_frames = clip.num_frames
    for key, shape in FRAME_SHAPES.items():
        arr = np.asarray(getattr(clip, key))
        if arr.shape != (num_frames, *shape):
            raise DataError(f"{path}: '{key}' has shape {arr.shape}, expected {(num_frames, *shape)}")
    if num_frames < 2:
        raise DataError(f"{path}: clip has {num_frames} frame(s); need at least 2")
    bad = nonfinite_frames(clip)
    if bad.any():
        raise DataError(
            f"{path}: NaN or inf in {int(bad.sum())} frame(s) ({format_segments(bad)}); "
            "repair them (`--repair` interpolates those frames) or fix the file"
        )
    for _, bad, what in rotation_glitch_notes(clip):
        raise DataError(f"{path}: {what} at frame(s) {format_segments(bad)}; repair them (`--repair` "
                        "interpolates those frames) or fix the file")
    for key in _QUAT_FIELDS:
        q = getattr(clip, key)
        err = np.abs(np.linalg.norm(q, axis=-1) - 1.0)
        if err.max() > QUAT_NORM_TOLERANCE:
            flat = int(np.argmax(err))
            frame, rest = np.unravel_index(flat, err.shape)[0], np.unravel_index(flat, err.shape)[1:]
            where = f"frame {frame}" + (f", body {BODY_NAMES[rest[0]]}" if rest else "")
            norm = float(np.linalg.norm(q.reshape(-1, 4)[flat]))
            raise DataError(f"{path}: non-unit quaternion in {key} (norm {norm:.4f} at {where})")
    root_err = float(np.abs(clip.root_pos - clip.body_pos[:, 0]).max())
    if root_err > ROOT_TOLERANCE_M:
        raise DataError(f"{path}: root_pos differs from body_pos of the pelvis by up to {root_err:.4f} m")
    root_angle = Rotation.from_quat(clip.root_quat_xyzw).inv() * Rotation.from_quat(clip.body_quat_xyzw[:, 0])
    if root_angle.magnitude().max() > ROTVEC_TOLERANCE_RAD:
        raise DataError(f"{path}: root_quat_xyzw differs from the pelvis body_quat_xyzw")
    angle, frame, body = rotvec_mismatch(clip.dof_rotvec, clip.body_quat_xyzw)
    if angle > ROTVEC_TOLERANCE_RAD:
        raise DataError(
            f"{path}: dof_rotvec disagrees with body_quat_xyzw by {np.degrees(angle):.2f} deg "
            f"(frame {frame}, joint {BODY_NAMES[body]})"
        )
    for key, allowed in (
        ("contact", (0, 1)),
        ("body_contact", (-1, 0, 1)),
        ("inferred_body_contact", (-1, 0, 1)),
    ):
        values = np.unique(getattr(clip, key))
        if not np.isin(values, allowed).all():
            raise DataError(f"{path}: '{key}' holds {values.tolist()}, allowed {list(allowed)}")
    if min_duration_s is not None and clip.duration < min_duration_s - 1e-9:
        raise DataError(
            f"{path}: clip too short: {clip.duration:.2f} s ({num_frames} frames at {clip.fps:g} fps), "
            f"need at least {min_duration_s:g} s"
        )


def clip_warnings(clip: HOIClip) -> list[str]:
    """Soft problems that do not stop a consumer but deserve a look (noisy skeleton, floor, jumps)."""
    notes = []
    std = bone_offsets(clip.body_pos, clip.body_quat_xyzw).std(axis=0).max(axis=-1)
    worst = int(np.argmax(std))
    if std[worst] > BONE_STD_WARN_M:
        notes.append(
            f"bone offsets vary over time (std up to {100 * std[worst]:.1f} cm at {BODY_NAMES[worst]}): "
            "body_pos is noisy or does not follow body_quat"
        )
    z = clip.body_pos[..., 2]
    if z.min() < FLOOR_WARN_M:
        frame, body = np.unravel_index(int(np.argmin(z)), z.shape)
        notes.append(f"body below the floor: {BODY_NAMES[body]} at z = {z.min():.3f} m (frame {frame})")
    if clip.object is not None:
        low = to_world(clip.object.hull_vertices(), clip.object_pos, clip.object_quat_xyzw)[..., 2].min(
            axis=1
        )
        if low.min() < FLOOR_WARN_M:
            notes.append(
                f"object below the floor: lowest point z = {low.min():.3f} m (frame {int(np.argmin(low))})"
            )
    step = np.linalg.norm(np.diff(clip.root_pos, axis=0), axis=1) * clip.fps
    jumps = step > ROOT_JUMP_WARN_M_S
    if jumps.any():
        notes.append(
            f"root moves faster than {ROOT_JUMP_WARN_M_S:g} m/s after frame(s) {format_segments(jumps)} "
            "(dropped frames?)"
        )
    for key, label in ROTATION_STREAMS.items():
        fast = rotation_steps_deg(getattr(clip, key)) * clip.fps > ROT_JUMP_DEG_S
        if fast.any():  # a lasting jump, not a one-frame spike: which side is right is unknown, so no repair
            notes.append(f"{label} turns faster than {ROT_JUMP_DEG_S:g} deg/s after frame(s) "
                         f"{format_segments(fast)} (dropped frames?)")
    return notes

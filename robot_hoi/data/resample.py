"""Time resampling of clips: positions linearly, rotations by slerp (scipy), labels from the nearest frame.

Works for any rate ratio (30 -> 50 Hz is fine). The output covers the same time span as the input:
t = 0, 1/fps_out, ... up to (T - 1) / fps_in.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from robot_hoi.data.clip import HOIClip
from robot_hoi.data.kinematics import make_quaternions_continuous, relative_rotvecs
from robot_hoi.data.segments import format_segments
from robot_hoi.data.validate import nonfinite_frames
from robot_hoi.errors import DataError, UserError


def resample_times(num_frames: int, fps_in: float, fps_out: float) -> np.ndarray:
    """Output sample times (s) covering [0, (num_frames - 1) / fps_in] at fps_out."""
    if fps_in <= 0 or fps_out <= 0:
        raise UserError(f"frame rates must be positive (got {fps_in} -> {fps_out})")
    span = (num_frames - 1) / fps_in
    count = int(np.floor(span * fps_out + 1e-6)) + 1
    return np.arange(count) / fps_out


def interpolate_linear(t_in: np.ndarray, values: np.ndarray, t_out: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation along axis 0 for any trailing shape; holds the ends outside t_in."""
    values = np.asarray(values, dtype=np.float64)
    if len(t_in) == 1:
        return np.repeat(values[:1], len(t_out), axis=0)
    idx = np.clip(np.searchsorted(t_in, t_out, side="right") - 1, 0, len(t_in) - 2)
    w = np.clip((t_out - t_in[idx]) / (t_in[idx + 1] - t_in[idx]), 0.0, 1.0)
    w = w.reshape(-1, *([1] * (values.ndim - 1)))
    return values[idx] * (1.0 - w) + values[idx + 1] * w


def interpolate_quats(t_in: np.ndarray, quat_xyzw: np.ndarray, t_out: np.ndarray) -> np.ndarray:
    """Slerp of (T, ..., 4) xyzw quaternion streams along axis 0; holds the ends outside t_in."""
    quat_xyzw = np.asarray(quat_xyzw, dtype=np.float64)
    streams = quat_xyzw.reshape(len(t_in), -1, 4)
    t_query = np.clip(t_out, t_in[0], t_in[-1])
    out = np.empty((len(t_out), streams.shape[1], 4))
    for s in range(streams.shape[1]):
        if len(t_in) == 1:
            out[:, s] = streams[0, s]
            continue
        out[:, s] = Slerp(t_in, Rotation.from_quat(streams[:, s]))(t_query).as_quat()
    out, _ = make_quaternions_continuous(out)
    return out.reshape(len(t_out), *quat_xyzw.shape[1:])


def _nearest(t_in: np.ndarray, t_out: np.ndarray) -> np.ndarray:
    idx = (
        np.clip(np.searchsorted(t_in, t_out), 1, len(t_in) - 1)
        if len(t_in) > 1
        else np.zeros(len(t_out), int)
    )
    if len(t_in) > 1:
        idx = np.where(np.abs(t_in[idx - 1] - t_out) <= np.abs(t_in[idx] - t_out), idx - 1, idx)
    return idx


def _interpolated_arrays(clip: HOIClip, frames: np.ndarray, t_in: np.ndarray, t_out: np.ndarray) -> dict:
    """Every per-frame array of `clip` sampled at t_out from the source frames `frames` (times t_in)."""
    body_quat = interpolate_quats(t_in, clip.body_quat_xyzw[frames], t_out)
    near = frames[_nearest(t_in, t_out)]
    body_pos = interpolate_linear(t_in, clip.body_pos[frames], t_out)
    return {
        "root_pos": body_pos[:, 0].copy(),
        "root_quat_xyzw": body_quat[:, 0].copy(),
        "dof_rotvec": relative_rotvecs(body_quat),
        "body_pos": body_pos,
        "body_quat_xyzw": body_quat,
        "object_pos": interpolate_linear(t_in, clip.object_pos[frames], t_out),
        "object_quat_xyzw": interpolate_quats(t_in, clip.object_quat_xyzw[frames], t_out),
        "contact": clip.contact[near].copy(),
        "body_contact": clip.body_contact[near].copy(),
        "inferred_contact": clip.inferred_contact[near].copy(),
        "inferred_body_contact": clip.inferred_body_contact[near].copy(),
    }


def resample_clip(clip: HOIClip, fps: float) -> HOIClip:
    """The clip at another frame rate (e.g. the policy's control rate)."""
    t_in = clip.times
    t_out = resample_times(clip.num_frames, clip.fps, fps)
    arrays = _interpolated_arrays(clip, np.arange(clip.num_frames), t_in, t_out)
    note = f"resampled from {clip.fps:g} to {fps:g} fps"
    return replace(clip, fps=float(fps), **arrays, problems=[*clip.problems, note])


def fill_missing_frames(clip: HOIClip) -> list[str]:
    """Fill frames holding NaN/inf by interpolating the good frames around them (in place)."""
    return fill_frames(clip, nonfinite_frames(clip), "with NaN/inf")


def fill_frames(clip: HOIClip, bad: np.ndarray, reason: str, keys: tuple[str, ...] | None = None) -> list[str]:
    """Replace the frames marked `bad` (T,) by interpolating the frames around them (in place); `keys` limits
    which arrays are replaced (default: all). Returns the note for clip.problems."""
    if not bad.any():
        return []
    good = np.flatnonzero(~bad)
    if len(good) < 2:
        raise DataError(f"{clip.name}: fewer than 2 frames without NaN/inf; nothing to interpolate from")
    times = clip.times
    filled = _interpolated_arrays(clip, good, times[good], times[bad])
    for key, values in filled.items():
        if keys is None or key in keys:
            getattr(clip, key)[bad] = values
    for key in ("body_quat_xyzw", "root_quat_xyzw", "object_quat_xyzw"):
        setattr(clip, key, make_quaternions_continuous(getattr(clip, key))[0])
    return [f"repaired: {int(bad.sum())} frame(s) {reason} ({format_segments(bad)}) filled by interpolation"]

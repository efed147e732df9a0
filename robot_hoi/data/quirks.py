"""Known defects of the InterMimic clips and how we repair them (each fix reports what it did).

* Frame-0 placeholder of physics-corrected clips: every kinematic column is 0 -> the frame is dropped.
* Quaternion sign flips (q vs -q): every quaternion stream is made continuous (hemisphere of the previous frame).
* `sub8` finger rows (InterAct's older OMOMO export): body_pos finger rows are shifted by 3 SMPL-X joints; the
  22 body joints, body_quat and dof_rotvec are right. Detected from bone-length statistics (a finger's offset
  in its parent's frame must be constant; shifted rows are not, while the body joints' are), not from the
  subject name. Fix: move the rows
  back (exact, verified by constant offsets afterwards) and rebuild the lost right thumb from body_quat and the
  left thumb's bone offsets mirrored (the skeleton is left/right symmetric to ~4 mm). If the known shift does not
  explain the data, every finger row is rebuilt from the template hand scaled to the subject's forearm and the
  note says the finger positions are approximate.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.data.clip import HOIClip
from robot_hoi.data.kinematics import bone_offsets, make_quaternions_continuous
from robot_hoi.data.layout import (
    BODY_INDEX,
    BODY_JOINTS,
    BODY_PARENTS,
    FINGERS,
    KINEMATIC_COLUMN_SLICES,
    L_FINGERS,
    R_FINGERS,
    R_THUMB,
    SHIFTED_FINGER_ROW_FIX,
    mirror_body,
)
from robot_hoi.data.template_skeleton import template_offsets

# A real skeleton's finger offsets vary < 1e-6 m over a clip; shifted rows vary by centimetres.
FINGER_OFFSET_STD_LIMIT_M = 0.002
_MIRROR_Y = np.array([1.0, -1.0, 1.0])


def leading_placeholder_frames(raw: np.ndarray) -> int:
    """How many leading rows of a (T, 591) matrix have every kinematic column exactly 0."""
    kinematic = np.concatenate([raw[:, s] for s in KINEMATIC_COLUMN_SLICES], axis=1)
    empty = np.all(kinematic == 0.0, axis=1)
    return int(np.argmin(empty)) if not empty.all() else len(empty)


def fix_quaternion_signs(clip: HOIClip) -> list[str]:
    """Make root, body and object quaternions continuous in time (in place)."""
    total = 0
    for key in ("root_quat_xyzw", "body_quat_xyzw", "object_quat_xyzw"):
        fixed, flips = make_quaternions_continuous(getattr(clip, key))
        setattr(clip, key, fixed)
        total += flips
    return [f"fixed: {total} quaternion sign flips (q vs -q) made continuous"] if total else []


def _rebuild_rows(body_pos: np.ndarray, body_quat_xyzw: np.ndarray, rows, offsets: np.ndarray) -> None:
    """Recompute body_pos[:, rows] by forward kinematics from their parents (rows in parent-first order)."""
    for j in rows:
        parent = BODY_PARENTS[j]
        body_pos[:, j] = body_pos[:, parent] + Rotation.from_quat(body_quat_xyzw[:, parent]).apply(offsets[j])


def finger_offset_spread(body_pos: np.ndarray, body_quat_xyzw: np.ndarray, rows=FINGERS) -> float:
    """Largest std over time (m) of the bone offsets of `rows`: ~0 for a consistent skeleton."""
    return float(bone_offsets(body_pos, body_quat_xyzw)[:, list(rows)].std(axis=0).max())


def fix_shifted_finger_rows(body_pos: np.ndarray, body_quat_xyzw: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Detect and repair shifted finger rows. Returns (body_pos, notes); body_pos unchanged when consistent."""
    # Noisy capture moves every joint alike; shifted rows make the fingers far worse than the body joints.
    body_spread = finger_offset_spread(body_pos, body_quat_xyzw, [j for j in BODY_JOINTS if j])
    if finger_offset_spread(body_pos, body_quat_xyzw) <= max(FINGER_OFFSET_STD_LIMIT_M, 3.0 * body_spread):
        return body_pos, []
    fixed = np.array(body_pos, copy=True)
    for correct_rows, buggy_rows in SHIFTED_FINGER_ROW_FIX:
        fixed[:, list(correct_rows)] = body_pos[:, list(buggy_rows)]
    recovered = [j for j in FINGERS if j not in R_THUMB]
    if finger_offset_spread(fixed, body_quat_xyzw, recovered) <= FINGER_OFFSET_STD_LIMIT_M:
        offsets = np.median(bone_offsets(fixed, body_quat_xyzw), axis=0)
        for j in R_THUMB:
            offsets[j] = offsets[mirror_body(j)] * _MIRROR_Y
        _rebuild_rows(fixed, body_quat_xyzw, R_THUMB, offsets)
        return fixed, [
            "fixed: finger rows of body_pos were shifted by 3 SMPL-X joints (InterAct OMOMO export bug, as in "
            "sub8 clips); rows moved back, right thumb rebuilt by mirroring the left thumb (~5 mm accuracy)"
        ]
    return rebuild_fingers_from_template(body_pos, body_quat_xyzw), [
        "finger positions unreliable (finger bone offsets vary over time in a way the known row shift does not "
        "explain): every finger row rebuilt from a template hand scaled to the forearm (approximate)"
    ]


def rebuild_fingers_from_template(body_pos: np.ndarray, body_quat_xyzw: np.ndarray) -> np.ndarray:
    """Finger rows from body_quat and the template hand, scaled per side by forearm length."""
    template = template_offsets()
    measured = np.median(bone_offsets(body_pos, body_quat_xyzw), axis=0)
    offsets = template.copy()
    out = np.array(body_pos, copy=True)
    for wrist, fingers in ((BODY_INDEX["L_Wrist"], L_FINGERS), (BODY_INDEX["R_Wrist"], R_FINGERS)):
        scale = np.linalg.norm(measured[wrist]) / np.linalg.norm(template[wrist])
        offsets[list(fingers)] = template[list(fingers)] * scale
        _rebuild_rows(out, body_quat_xyzw, fingers, offsets)
    return out

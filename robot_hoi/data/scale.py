"""Human -> robot scaling by height ratio (as OmniRetarget does: robot_height / human_height).

Subject heights come from the SOURCES.md table; an unknown subject's height is estimated from the clip's own
skeleton (bone offsets) and reported as estimated.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from robot_hoi.data.clip import HOIClip
from robot_hoi.data.kinematics import bone_offsets, estimate_height_from_offsets
from robot_hoi.data.layout import SUBJECT_HEIGHTS_M
from robot_hoi.errors import UserError
from robot_hoi.paths import CONFIGS_DIR

DEFAULT_ROBOT_HEIGHT_M = 1.32  # Unitree G1 standing height
DEFAULT_EMBODIMENT = "g1_inspire"


@dataclass(frozen=True)
class HeightInfo:
    height_m: float
    source: str  # "table" | "estimated" | "synthetic" | whatever the clip says


def subject_height(subject: str | None, body_pos: np.ndarray, body_quat_xyzw: np.ndarray) -> HeightInfo:
    """The subject's height from the table, else estimated from the skeleton in the clip."""
    if subject is not None and subject in SUBJECT_HEIGHTS_M:
        return HeightInfo(SUBJECT_HEIGHTS_M[subject], "table")
    offsets = np.median(bone_offsets(body_pos, body_quat_xyzw), axis=0)
    return HeightInfo(round(estimate_height_from_offsets(offsets), 3), "estimated")


def robot_height_from_embodiment(name_or_path: str | Path = DEFAULT_EMBODIMENT) -> float:
    """`robot_height` from configs/embodiments/<name>.yaml (or a YAML path); 1.32 m when the key is absent."""
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = CONFIGS_DIR / "embodiments" / f"{name_or_path}.yaml"
    if not path.is_file():
        raise UserError(f"{path}: embodiment config not found")
    try:
        cfg = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise UserError(f"{path}: not valid YAML ({exc})") from exc
    height = (
        cfg.get("robot_height", DEFAULT_ROBOT_HEIGHT_M) if isinstance(cfg, dict) else DEFAULT_ROBOT_HEIGHT_M
    )
    if not isinstance(height, int | float) or not 0.3 < float(height) < 3.0:
        raise UserError(f"{path}: robot_height must be a height in metres, got {height!r}")
    return float(height)


def human_to_robot_scale(clip: HOIClip, robot_height_m: float | None = None) -> float:
    """robot_height / subject height (the clip's height, or estimated from its skeleton)."""
    robot_height_m = DEFAULT_ROBOT_HEIGHT_M if robot_height_m is None else robot_height_m
    human = clip.subject_height_m
    if human is None:
        human = subject_height(clip.subject, clip.body_pos, clip.body_quat_xyzw).height_m
    return float(robot_height_m) / float(human)


def scale_clip(clip: HOIClip, factor: float, *, scale_object: bool = True) -> HOIClip:
    """Scale every world position about the world origin (z = 0 stays the floor).

    Rotations and contact labels are unchanged. With scale_object the object's geometry and trajectory are
    scaled too (the interaction stays consistent); without it only the human is scaled.
    """
    if not factor > 0:
        raise UserError(f"scale factor must be positive, got {factor}")
    obj = clip.object
    if scale_object and obj is not None:
        obj = replace(obj, vertices=obj.vertices * factor, sample_points=obj.sample_points * factor,
                      mass_kg=None if obj.mass_kg is None else obj.mass_kg * factor**3)  # fmt: skip
    height = None if clip.subject_height_m is None else clip.subject_height_m * factor
    note = f"scaled by {factor:.4f}" + ("" if scale_object else " (human only)")
    return replace(
        clip,
        root_pos=clip.root_pos * factor,
        body_pos=clip.body_pos * factor,
        object_pos=clip.object_pos * factor if scale_object else clip.object_pos.copy(),
        object=obj,
        subject_height_m=height,
        problems=[*clip.problems, note],
    )

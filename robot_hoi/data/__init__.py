"""HOI clip data: the 591-column InterMimic layout, `HOIClip`, readers, validation, contacts, the synthetic clip.

Public entry points (imported lazily, so `robot-hoi --help` stays fast):
    load_clip(path, *, objects_dir=None, object_optional=False, repair_missing=False, ...) -> HOIClip
    HOIClip (.save(path.npz)), ObjectAsset
    default_clip(kind="lift_carry", *, seed=0, artifacts=()) -> HOIClip   (license-free synthetic clip)
    validate_clip(clip, *, path), clip_warnings(clip)
    infer_contacts(body_pos, obj, object_pos, object_quat_xyzw, fps) -> ContactEstimate
    resample_clip(clip, fps), scale_clip(clip, factor), human_to_robot_scale(clip, robot_height_m)
    clip_summary(clip, path) -> dict   (what `robot-hoi data inspect --json` prints)

Conventions: z-up world, floor at z = 0, metres, radians, quaternions xyzw (scipy) in every `*_xyzw` field.
"""

from __future__ import annotations

import importlib

_LAZY = {
    "HOIClip": "robot_hoi.data.clip",
    "load_clip": "robot_hoi.data.clip",
    "ObjectAsset": "robot_hoi.data.objects",
    "box_asset": "robot_hoi.data.objects",
    "default_clip": "robot_hoi.data.synth",
    "validate_clip": "robot_hoi.data.validate",
    "clip_warnings": "robot_hoi.data.validate",
    "ContactEstimate": "robot_hoi.data.contacts",
    "ContactParams": "robot_hoi.data.contacts",
    "infer_contacts": "robot_hoi.data.contacts",
    "resample_clip": "robot_hoi.data.resample",
    "scale_clip": "robot_hoi.data.scale",
    "human_to_robot_scale": "robot_hoi.data.scale",
    "robot_height_from_embodiment": "robot_hoi.data.scale",
    "clip_summary": "robot_hoi.data.summary",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'robot_hoi.data' has no attribute {name!r}")

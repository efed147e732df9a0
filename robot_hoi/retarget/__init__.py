"""Kinematic retarget of human-object clips onto the robot: the reference the RL teachers track and start from.

    targets_from_clip(clip, cfg, scale=None, mapping=None) -> RobotTargets     (targets.py: the mapping)
    retarget_clip(clip, cfg, model=None, scale=None, options=None) -> RetargetResult (.motion: RobotMotion)
    RobotMotion.save(path.npz) / RobotMotion.load(path.npz)                     (motion.py)
    IKSolver(model, link_names, ...).solve(targets, weights, ...)               (ik.py: any MuJoCo model)
    build_report(result) / format_report(report)                                (report.py)
    write_video(motion, cfg, model, path.mp4, object_asset)                     (video.py)

Attributes load lazily, so `robot-hoi --help` does not import mujoco.
"""

from __future__ import annotations

import importlib

_LAZY = {
    "RobotTargets": "robot_hoi.retarget.targets",
    "TargetMapping": "robot_hoi.retarget.targets",
    "targets_from_clip": "robot_hoi.retarget.targets",
    "IKSolver": "robot_hoi.retarget.ik",
    "IKSettings": "robot_hoi.retarget.ik",
    "IKResult": "robot_hoi.retarget.ik",
    "RobotMotion": "robot_hoi.retarget.motion",
    "GraspRule": "robot_hoi.retarget.hands",
    "RetargetOptions": "robot_hoi.retarget.pipeline",
    "RetargetResult": "robot_hoi.retarget.pipeline",
    "retarget_clip": "robot_hoi.retarget.pipeline",
    "retarget_targets": "robot_hoi.retarget.pipeline",
    "build_report": "robot_hoi.retarget.report",
    "format_report": "robot_hoi.retarget.report",
    "write_video": "robot_hoi.retarget.video",
}
__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'robot_hoi.retarget' has no attribute {name!r}")

"""The reference motion a deployable policy tracks, in the deploy runtime's sidecar format (deploy/motion.py)."""

from __future__ import annotations

import numpy as np

from deploy.motion import ReferenceMotion as DeployMotion


def deploy_motion(reference, source: str = "<export>"):
    """robot_hoi ReferenceMotion (the env's robot-space reference) -> deploy.motion.ReferenceMotion."""
    as_np = lambda t: np.asarray(t.detach().cpu().numpy(), dtype=np.float64)  # noqa: E731
    qpos = as_np(reference.robot_qpos)
    return DeployMotion(
        fps=float(reference.fps),
        joint_pos=as_np(reference.joint_pos),
        root_pos=qpos[:, 0:3],
        root_quat_wxyz=qpos[:, 3:7],
        link_pos=as_np(reference.link_pos),
        object_pos=as_np(reference.object_pos),
        object_quat_wxyz=as_np(reference.object_quat_wxyz),
        source=source,
    )

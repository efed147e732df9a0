"""Posing the template skeleton for synthetic clips: aim rotations, two-bone IK, whole-body assembly.

Everything is vectorised over frames. Rotations are scipy `Rotation`s; positions come out of forward kinematics
of the posed global rotations, so body_pos, body_quat and dof_rotvec are consistent by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.data.kinematics import forward_kinematics
from robot_hoi.data.layout import BODY_INDEX, BODY_PARENTS, L_FINGERS, NUM_BODIES, R_FINGERS

B = BODY_INDEX


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _frame(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Orthonormal frames (..., 3, 3) with columns [primary, secondary made orthogonal, their cross]."""
    a = _unit(primary)
    b = _unit(secondary - np.sum(secondary * a, axis=-1, keepdims=True) * a)
    return np.stack([a, b, np.cross(a, b)], axis=-1)


def aim_rotation(local_primary, local_secondary, world_primary, world_secondary) -> Rotation:
    """Rotation taking local_primary onto world_primary exactly and local_secondary into the plane of
    (world_primary, world_secondary) on the same side."""
    world_primary = np.atleast_2d(world_primary)
    world_secondary = np.broadcast_to(world_secondary, world_primary.shape)
    local = _frame(np.asarray(local_primary, float), np.asarray(local_secondary, float))
    world = _frame(world_primary, world_secondary)
    return Rotation.from_matrix(world @ local.T)


def two_bone_ik(root: np.ndarray, target: np.ndarray, len1: float, len2: float, pole: np.ndarray):
    """Middle joint for a two-bone chain reaching `target` from `root`, bending towards `pole`.

    Returns (mid, end, hinge_axis, stretch) where end is the target pulled into reach (equal to the target when
    reachable) and stretch = |target - root| / (len1 + len2).
    """
    delta = target - root
    dist = np.linalg.norm(delta, axis=-1)
    stretch = dist / (len1 + len2)
    reach = np.clip(dist, abs(len1 - len2) + 1e-6, (len1 + len2) * (1.0 - 1e-9))
    u = _unit(delta)
    side = _unit(pole - np.sum(pole * u, axis=-1, keepdims=True) * u)
    cos_a = np.clip((len1**2 + reach**2 - len2**2) / (2.0 * len1 * reach), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a**2)
    mid = root + len1 * (cos_a[:, None] * u + sin_a[:, None] * side)
    end = root + reach[:, None] * u
    return mid, end, _unit(np.cross(u, side)), stretch


@dataclass(frozen=True)
class Limb:
    upper: int  # body whose rotation moves the middle joint (thigh / upper arm)
    lower: int  # body whose rotation moves the end joint (shank / forearm)
    end: int  # end joint body (ankle / wrist)
    tpose_pole: tuple[float, float, float]  # where the middle joint points in the T-pose when the limb bends


LEGS = {
    "L": Limb(B["L_Hip"], B["L_Knee"], B["L_Ankle"], (1.0, 0.0, 0.0)),
    "R": Limb(B["R_Hip"], B["R_Knee"], B["R_Ankle"], (1.0, 0.0, 0.0)),
}
ARMS = {
    "L": Limb(B["L_Shoulder"], B["L_Elbow"], B["L_Wrist"], (-1.0, 0.0, 0.0)),
    "R": Limb(B["R_Shoulder"], B["R_Elbow"], B["R_Wrist"], (-1.0, 0.0, 0.0)),
}


class PoseBuilder:
    """Global rotations for all 52 bodies over T frames, filled part by part, then FK to positions.

    Bodies whose rotation is never set follow their parent (zero joint rotation), like the real clips' fingers.
    """

    def __init__(self, offsets: np.ndarray, root_pos: np.ndarray):
        self.offsets = offsets
        self.root_pos = np.asarray(root_pos, dtype=np.float64)
        self.num_frames = len(self.root_pos)
        self.rot: dict[int, Rotation] = {}
        self.stretch: dict[str, np.ndarray] = {}

    def set_global(self, body: int, rotation: Rotation) -> None:
        self.rot[body] = rotation

    def set_local(self, body: int, local: Rotation) -> None:
        self.rot[body] = self.global_rot(BODY_PARENTS[body]) * local

    def global_rot(self, body: int) -> Rotation:
        if body in self.rot:
            return self.rot[body]
        return self.global_rot(BODY_PARENTS[body]) if body else Rotation.identity(self.num_frames)

    def joint_pos(self, body: int) -> np.ndarray:
        """World position of a body whose ancestors' rotations are already set."""
        if body == 0:
            return self.root_pos
        parent = BODY_PARENTS[body]
        return self.joint_pos(parent) + self.global_rot(parent).apply(self.offsets[body])

    def solve_limb(self, name: str, limb: Limb, target: np.ndarray, pole: np.ndarray) -> None:
        """Rotate upper and lower bones so the end joint lands on `target`, bending towards `pole`."""
        root = self.joint_pos(limb.upper)
        off1, off2 = self.offsets[limb.lower], self.offsets[limb.end]
        mid, end, hinge, stretch = two_bone_ik(root, target, np.linalg.norm(off1), np.linalg.norm(off2), pole)
        self.stretch[name] = stretch
        local_hinge = np.cross(off1 + off2, limb.tpose_pole)
        self.rot[limb.upper] = aim_rotation(off1, local_hinge, mid - root, hinge)
        self.rot[limb.lower] = aim_rotation(off2, local_hinge, end - mid, hinge)

    def body_quats(self) -> np.ndarray:
        """(T, 52, 4) xyzw global rotations (unset bodies inherit their parent's)."""
        return np.stack([self.global_rot(j).as_quat() for j in range(NUM_BODIES)], axis=1)

    def finish(self) -> tuple[np.ndarray, np.ndarray]:
        """(body_pos (T, 52, 3), body_quat_xyzw (T, 52, 4)) by forward kinematics."""
        for j in L_FINGERS + R_FINGERS:  # flat hands: fingers follow the wrist (zero finger joint rotations)
            self.rot.pop(j, None)
        quats = self.body_quats()
        return forward_kinematics(self.root_pos, quats, self.offsets), quats


def hand_rotation(side: str, fingers_world: np.ndarray, palm_normal_world: np.ndarray) -> Rotation:
    """Global hand rotation whose fingers point along `fingers_world` and whose palm faces `palm_normal_world`.

    In the T-pose the left hand's fingers point +y, the right hand's -y, and both palms face -z.
    """
    fingers_local = (0.0, 1.0, 0.0) if side == "L" else (0.0, -1.0, 0.0)
    return aim_rotation(fingers_local, (0.0, 0.0, -1.0), fingers_world, palm_normal_world)


def _about(axis: tuple[float, float, float], angle) -> Rotation:
    angle = np.asarray(angle, dtype=np.float64)
    return Rotation.from_rotvec(angle[..., None] * np.asarray(axis))


def yaw(angle) -> Rotation:
    return _about((0.0, 0.0, 1.0), angle)


def pitch(angle) -> Rotation:
    """Positive pitch leans forward (+x) in the PHC frame: rotation about +y."""
    return _about((0.0, 1.0, 0.0), angle)

"""Plain data types for a robot's physical description (bodies, inertials, joints, collision shapes, sites).

The description is generator-neutral: robot_hoi.embodiment.mjcf turns it into a MuJoCo model and
robot_hoi.embodiment.urdf into URDF text. Orientations are stored as quaternions in MuJoCo's wxyz order
(field names say so); `rpy_to_quat_wxyz` converts URDF roll-pitch-yaw where the source numbers are URDF.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

Vec3 = tuple[float, float, float]
QuatWxyz = tuple[float, float, float, float]
IDENTITY_WXYZ: QuatWxyz = (1.0, 0.0, 0.0, 0.0)


def rpy_to_quat_wxyz(roll: float, pitch: float, yaw: float) -> QuatWxyz:
    """URDF rpy (fixed-axis x, then y, then z) -> unit quaternion, wxyz."""
    x, y, z, w = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_quat()
    return (float(w), float(x), float(y), float(z))


def quat_wxyz_to_matrix(quat_wxyz) -> np.ndarray:
    w, x, y, z = quat_wxyz
    return Rotation.from_quat([x, y, z, w]).as_matrix()


@dataclass(frozen=True)
class Inertial:
    """Mass properties in the body frame: centre of mass `com` and EITHER a full inertia tensor about the com
    (`full` = ixx, iyy, izz, ixy, ixz, iyz, URDF's numbers) OR principal moments `diag` with the principal-axes
    orientation `quat_wxyz` (MuJoCo's compiled form)."""

    mass: float
    com: Vec3
    diag: Vec3 | None = None
    quat_wxyz: QuatWxyz = IDENTITY_WXYZ
    full: tuple[float, float, float, float, float, float] | None = None

    def __post_init__(self) -> None:
        if (self.diag is None) == (self.full is None):
            raise ValueError("Inertial needs exactly one of `diag` or `full`")

    def tensor(self) -> np.ndarray:
        """3x3 inertia tensor about the com, in body-frame axes."""
        if self.full is not None:
            ixx, iyy, izz, ixy, ixz, iyz = self.full
            return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=float)
        rot = quat_wxyz_to_matrix(self.quat_wxyz)
        return rot @ np.diag(self.diag) @ rot.T


@dataclass(frozen=True)
class Mimic:
    """A passive joint driven by another: q = multiplier * q_driver + offset (URDF <mimic>)."""

    joint: str
    multiplier: float
    offset: float = 0.0


@dataclass(frozen=True)
class JointSpec:
    """A hinge joint between a body and its parent, located at the body origin."""

    name: str
    axis: Vec3
    range: tuple[float, float]
    effort: float  # N·m, actuator torque limit
    velocity: float  # rad/s, URDF velocity limit (informational in MuJoCo)
    armature: float = 0.0  # kg·m², reflected rotor inertia
    damping: float = 0.0  # N·m·s/rad, passive joint damping
    mimic: Mimic | None = None


@dataclass(frozen=True)
class GeomSpec:
    """Collision primitive. capsule: `size` = (radius,) between `fromto` end points; box: half sizes at
    pos/quat; sphere: (radius,) at pos."""

    name: str
    type: str  # "capsule" | "box" | "sphere"
    size: tuple[float, ...]
    pos: Vec3 = (0.0, 0.0, 0.0)
    quat_wxyz: QuatWxyz = IDENTITY_WXYZ
    fromto: tuple[float, float, float, float, float, float] | None = None

    def __post_init__(self) -> None:
        expected = {"capsule": 1, "sphere": 1, "box": 3}
        if self.type not in expected or len(self.size) != expected[self.type]:
            raise ValueError(f"geom {self.name}: bad type/size {self.type} {self.size}")
        if self.type == "capsule" and self.fromto is None:
            raise ValueError(f"geom {self.name}: capsule needs fromto")


@dataclass(frozen=True)
class SiteSpec:
    name: str
    pos: Vec3


@dataclass(frozen=True)
class VisualMesh:
    """A visual-only mesh (Unitree STL file name, looked up in the reference mesh folder when present)."""

    file: str
    pos: Vec3 = (0.0, 0.0, 0.0)
    rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)


@dataclass(frozen=True)
class BodySpec:
    """One rigid link. `pos`/`quat_wxyz` place it in its parent's frame; `joint` None = fixed to the parent."""

    name: str
    parent: str  # "world" for the floating base
    pos: Vec3
    quat_wxyz: QuatWxyz
    inertial: Inertial
    joint: JointSpec | None = None
    geoms: tuple[GeomSpec, ...] = ()
    sites: tuple[SiteSpec, ...] = ()
    meshes: tuple[VisualMesh, ...] = ()  # optional, viewer only
    # The URDF rpy `quat_wxyz` was made from, when the source is a URDF; the URDF writer then reuses it verbatim
    # instead of converting back (Inspire thumb frames sit near the pitch = -pi/2 gimbal lock).
    rpy: Vec3 | None = None


@dataclass(frozen=True)
class RobotDescription:
    """A floating-base robot: bodies listed parent-before-child (MuJoCo's depth-first order)."""

    name: str
    base_joint: str
    bodies: tuple[BodySpec, ...]
    # body pairs whose collision geoms touch by construction (only matters with self-collision on)
    contact_excludes: tuple[tuple[str, str], ...] = field(default=())

    def body(self, name: str) -> BodySpec:
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(name)

    @property
    def joints(self) -> tuple[JointSpec, ...]:
        return tuple(b.joint for b in self.bodies if b.joint is not None)

    def joint(self, name: str) -> JointSpec:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    @property
    def actuated_joints(self) -> tuple[JointSpec, ...]:
        return tuple(j for j in self.joints if j.mimic is None)

    @property
    def passive_joints(self) -> tuple[JointSpec, ...]:
        return tuple(j for j in self.joints if j.mimic is not None)

    @property
    def site_names(self) -> tuple[str, ...]:
        return tuple(s.name for b in self.bodies for s in b.sites)

    @property
    def total_mass(self) -> float:
        return sum(b.inertial.mass for b in self.bodies)

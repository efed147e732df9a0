"""The Unitree G1 29-DoF (rev 1.0) with two Inspire DFQ hands: the ONE physical description of the robot.

Everything physical lives here (and in inspire_spec.py for the hands): body tree, frames, inertials, joint
axes/ranges/effort limits, armature, collision primitives and named sites. robot_hoi.embodiment.mjcf and
robot_hoi.embodiment.urdf generate the MuJoCo model and urdf/g1_inspire.urdf from it.

Sources (numbers only): body frames and inertials from Unitree's `g1_29dof_rev_1_0.xml` (unitree_ros), except
the wrist yaw links, whose inertial is the DFQ URDF's (rubber hand removed); effort limits = the MJCF's
`actuatorfrcrange`; velocity limits from `g1_29dof_rev_1_0.urdf`; armature per motor class from mjlab's G1
constants. Collision primitives were fitted by us to Unitree's STL meshes (the sole box matches the foot mesh:
0.208 m x 0.0756 m, bottom 35.4 mm below the ankle-roll frame).
"""

from __future__ import annotations

from dataclasses import dataclass

from robot_hoi.embodiment.inspire_spec import left_hand, right_hand
from robot_hoi.embodiment.spec_types import (
    BodySpec,
    GeomSpec,
    Inertial,
    JointSpec,
    RobotDescription,
    SiteSpec,
    VisualMesh,
)


@dataclass(frozen=True)
class MotorClass:
    armature: float  # kg·m², reflected rotor inertia (mjlab)
    effort: float  # N·m (Unitree MJCF actuatorfrcrange)
    velocity: float  # rad/s (Unitree URDF)


MOTOR_CLASSES = {
    "7520-14": MotorClass(armature=0.010178, effort=88.0, velocity=32.0),
    "7520-22": MotorClass(armature=0.025102, effort=139.0, velocity=20.0),
    "2x5020": MotorClass(armature=0.007219, effort=50.0, velocity=30.0),  # ankle / waist roll-pitch linkages
    "5020": MotorClass(armature=0.003610, effort=25.0, velocity=37.0),
    "4010": MotorClass(armature=0.004250, effort=5.0, velocity=22.0),
}
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}

# (link, parent, pos, quat_wxyz, (mass, com, principal-axes quat_wxyz, principal moments), joint | None)
# joint = (name, axis, (lower, upper), motor class). Order = Unitree motor order.
_G1_LINKS = (
    ("pelvis", "world", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
     (3.813, (0.0, 0.0, -0.07605), (1.0, 0.0, -0.000399148, 0.0), (0.010549, 0.0093089, 0.0079184)),
     None),
    ("left_hip_pitch_link", "pelvis", (0.0, 0.064452, -0.1027), (1.0, 0.0, 0.0, 0.0),
     (1.35, (0.002741, 0.047791, -0.02606), (0.954862, 0.293964, 0.0302556, 0.030122), (0.00181517, 0.00153422, 0.00116212)),
     ("left_hip_pitch_joint", "y", (-2.5307, 2.8798), "7520-14")),
    ("left_hip_roll_link", "left_hip_pitch_link", (0.0, 0.052, -0.030465), (0.996179, 0.0, -0.0873386, 0.0),
     (1.52, (0.029812, -0.001045, -0.087934), (0.977808, -1.97119e-05, 0.205576, -0.0403793), (0.00254986, 0.00241169, 0.00148755)),
     ("left_hip_roll_joint", "x", (-0.5236, 2.9671), "7520-22")),
    ("left_hip_yaw_link", "left_hip_roll_link", (0.025001, 0.0, -0.12412), (1.0, 0.0, 0.0, 0.0),
     (1.702, (-0.057709, -0.010981, -0.15078), (0.600598, 0.15832, 0.223482, 0.751181), (0.00776166, 0.00717575, 0.00160139)),
     ("left_hip_yaw_joint", "z", (-2.7576, 2.7576), "7520-14")),
    ("left_knee_link", "left_hip_yaw_link", (-0.078273, 0.0021489, -0.17734), (0.996179, 0.0, 0.0873386, 0.0),
     (1.932, (0.005457, 0.003964, -0.12074), (0.923418, -0.0327699, 0.0158246, 0.382067), (0.0113804, 0.0112778, 0.00146458)),
     ("left_knee_joint", "y", (-0.087267, 2.8798), "7520-22")),
    ("left_ankle_pitch_link", "left_knee_link", (0.0, -9.4445e-05, -0.30001), (1.0, 0.0, 0.0, 0.0),
     (0.074, (-0.007269, 0.0, 0.011137), (0.603053, 0.369225, 0.369225, 0.603053), (1.89e-05, 1.40805e-05, 6.9195e-06)),
     ("left_ankle_pitch_joint", "y", (-0.87267, 0.5236), "2x5020")),
    ("left_ankle_roll_link", "left_ankle_pitch_link", (0.0, 0.0, -0.017558), (1.0, 0.0, 0.0, 0.0),
     (0.608, (0.026505, 0.0, -0.016425), (-0.000481092, 0.728482, -0.000618967, 0.685065), (0.00167218, 0.0016161, 0.000217621)),
     ("left_ankle_roll_joint", "x", (-0.2618, 0.2618), "2x5020")),
    ("right_hip_pitch_link", "pelvis", (0.0, -0.064452, -0.1027), (1.0, 0.0, 0.0, 0.0),
     (1.35, (0.002741, -0.047791, -0.02606), (0.954862, -0.293964, 0.0302556, -0.030122), (0.00181517, 0.00153422, 0.00116212)),
     ("right_hip_pitch_joint", "y", (-2.5307, 2.8798), "7520-14")),
    ("right_hip_roll_link", "right_hip_pitch_link", (0.0, -0.052, -0.030465), (0.996179, 0.0, -0.0873386, 0.0),
     (1.52, (0.029812, 0.001045, -0.087934), (0.977808, 1.97119e-05, 0.205576, 0.0403793), (0.00254986, 0.00241169, 0.00148755)),
     ("right_hip_roll_joint", "x", (-2.9671, 0.5236), "7520-22")),
    ("right_hip_yaw_link", "right_hip_roll_link", (0.025001, 0.0, -0.12412), (1.0, 0.0, 0.0, 0.0),
     (1.702, (-0.057709, 0.010981, -0.15078), (0.751181, 0.223482, 0.15832, 0.600598), (0.00776166, 0.00717575, 0.00160139)),
     ("right_hip_yaw_joint", "z", (-2.7576, 2.7576), "7520-14")),
    ("right_knee_link", "right_hip_yaw_link", (-0.078273, -0.0021489, -0.17734), (0.996179, 0.0, 0.0873386, 0.0),
     (1.932, (0.005457, -0.003964, -0.12074), (0.923439, 0.0345276, 0.0116333, -0.382012), (0.011374, 0.0112843, 0.00146452)),
     ("right_knee_joint", "y", (-0.087267, 2.8798), "7520-22")),
    ("right_ankle_pitch_link", "right_knee_link", (0.0, 9.4445e-05, -0.30001), (1.0, 0.0, 0.0, 0.0),
     (0.074, (-0.007269, 0.0, 0.011137), (0.603053, 0.369225, 0.369225, 0.603053), (1.89e-05, 1.40805e-05, 6.9195e-06)),
     ("right_ankle_pitch_joint", "y", (-0.87267, 0.5236), "2x5020")),
    ("right_ankle_roll_link", "right_ankle_pitch_link", (0.0, 0.0, -0.017558), (1.0, 0.0, 0.0, 0.0),
     (0.608, (0.026505, 0.0, -0.016425), (0.000481092, 0.728482, 0.000618967, 0.685065), (0.00167218, 0.0016161, 0.000217621)),
     ("right_ankle_roll_joint", "x", (-0.2618, 0.2618), "2x5020")),
    ("waist_yaw_link", "pelvis", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
     (0.214, (0.003494, 0.000233, 0.018034), (0.289697, 0.591001, -0.337795, 0.672821), (0.000163531, 0.000107714, 0.000102205)),
     ("waist_yaw_joint", "z", (-2.618, 2.618), "7520-14")),
    ("waist_roll_link", "waist_yaw_link", (-0.0039635, 0.0, 0.044), (1.0, 0.0, 0.0, 0.0),
     (0.086, (0.0, 2.3e-05, 0.0), (0.5, 0.5, -0.5, 0.5), (8.245e-06, 7.079e-06, 6.339e-06)),
     ("waist_roll_joint", "x", (-0.52, 0.52), "2x5020")),
    ("torso_link", "waist_roll_link", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
     (7.818, (0.00203158, 0.000339683, 0.184568), (0.999803, -6.03319e-05, 0.0198256, 0.00131986), (0.121847, 0.109825, 0.0273735)),
     ("waist_pitch_joint", "y", (-0.52, 0.52), "2x5020")),
    ("left_shoulder_pitch_link", "torso_link", (0.0039563, 0.10022, 0.24778), (0.990264, 0.139201, 1.38722e-05, -9.86868e-05),
     (0.718, (0.0, 0.035892, -0.011628), (0.654152, 0.0130458, -0.326267, 0.68225), (0.000465864, 0.000432842, 0.000406394)),
     ("left_shoulder_pitch_joint", "y", (-3.0892, 2.6704), "5020")),
    ("left_shoulder_roll_link", "left_shoulder_pitch_link", (0.0, 0.038, -0.013831), (0.990268, -0.139172, 0.0, 0.0),
     (0.643, (-0.000227, 0.00727, -0.063243), (0.701256, -0.0196223, -0.00710317, 0.712604), (0.000691311, 0.000618011, 0.000388977)),
     ("left_shoulder_roll_joint", "x", (-1.5882, 2.2515), "5020")),
    ("left_shoulder_yaw_link", "left_shoulder_roll_link", (0.0, 0.00624, -0.1032), (1.0, 0.0, 0.0, 0.0),
     (0.734, (0.010773, -0.002949, -0.072009), (0.716879, -0.0964829, -0.0679942, 0.687134), (0.00106187, 0.00103217, 0.000400661)),
     ("left_shoulder_yaw_joint", "z", (-2.618, 2.618), "5020")),
    ("left_elbow_link", "left_shoulder_yaw_link", (0.015783, 0.0, -0.080518), (1.0, 0.0, 0.0, 0.0),
     (0.6, (0.064956, 0.004454, -0.010062), (0.541765, 0.636132, 0.388821, 0.388129), (0.000443035, 0.000421612, 0.000259353)),
     ("left_elbow_joint", "y", (-1.0472, 2.0944), "5020")),
    ("left_wrist_roll_link", "left_elbow_link", (0.1, 0.00188791, -0.01), (1.0, 0.0, 0.0, 0.0),
     (0.085445, (0.0171394, 0.000537591, 4.8864e-07), (0.575338, 0.411667, -0.574906, 0.411094), (5.48211e-05, 4.96646e-05, 3.57798e-05)),
     ("left_wrist_roll_joint", "x", (-1.97222, 1.97222), "5020")),
    ("left_wrist_pitch_link", "left_wrist_roll_link", (0.038, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
     (0.48405, (0.0229999, -0.00111685, -0.00111658), (0.249998, 0.661363, 0.293036, 0.643608), (0.000430353, 0.000429873, 0.000164648)),
     ("left_wrist_pitch_joint", "y", (-1.61443, 1.61443), "4010")),
    ("left_wrist_yaw_link", "left_wrist_pitch_link", (0.046, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
     (0.254576, (0.0708244, 0.000191745, 0.00161742), (0.510571, 0.526295, 0.468078, 0.493188), (0.000646113, 0.000559993, 0.000147566)),
     ("left_wrist_yaw_joint", "z", (-1.61443, 1.61443), "4010")),
    ("right_shoulder_pitch_link", "torso_link", (0.0039563, -0.10021, 0.24778), (0.990264, -0.139201, 1.38722e-05, 9.86868e-05),
     (0.718, (0.0, -0.035892, -0.011628), (0.68225, -0.326267, 0.0130458, 0.654152), (0.000465864, 0.000432842, 0.000406394)),
     ("right_shoulder_pitch_joint", "y", (-3.0892, 2.6704), "5020")),
    ("right_shoulder_roll_link", "right_shoulder_pitch_link", (0.0, -0.038, -0.013831), (0.990268, 0.139172, 0.0, 0.0),
     (0.643, (-0.000227, -0.00727, -0.063243), (0.712604, -0.00710317, -0.0196223, 0.701256), (0.000691311, 0.000618011, 0.000388977)),
     ("right_shoulder_roll_joint", "x", (-2.2515, 1.5882), "5020")),
    ("right_shoulder_yaw_link", "right_shoulder_roll_link", (0.0, -0.00624, -0.1032), (1.0, 0.0, 0.0, 0.0),
     (0.734, (0.010773, 0.002949, -0.072009), (0.687134, -0.0679942, -0.0964829, 0.716879), (0.00106187, 0.00103217, 0.000400661)),
     ("right_shoulder_yaw_joint", "z", (-2.618, 2.618), "5020")),
    ("right_elbow_link", "right_shoulder_yaw_link", (0.015783, 0.0, -0.080518), (1.0, 0.0, 0.0, 0.0),
     (0.6, (0.064956, -0.004454, -0.010062), (0.388129, 0.388821, 0.636132, 0.541765), (0.000443035, 0.000421612, 0.000259353)),
     ("right_elbow_joint", "y", (-1.0472, 2.0944), "5020")),
    ("right_wrist_roll_link", "right_elbow_link", (0.1, -0.00188791, -0.01), (1.0, 0.0, 0.0, 0.0),
     (0.085445, (0.0171394, -0.000537591, 4.8864e-07), (0.411667, 0.575338, -0.411094, 0.574906), (5.48211e-05, 4.96646e-05, 3.57798e-05)),
     ("right_wrist_roll_joint", "x", (-1.97222, 1.97222), "5020")),
    ("right_wrist_pitch_link", "right_wrist_roll_link", (0.038, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
     (0.48405, (0.0229999, 0.00111685, -0.00111658), (0.643608, 0.293036, 0.661363, 0.249998), (0.000430353, 0.000429873, 0.000164648)),
     ("right_wrist_pitch_joint", "y", (-1.61443, 1.61443), "4010")),
    ("right_wrist_yaw_link", "right_wrist_pitch_link", (0.046, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
     (0.254576, (0.0708244, -0.000191745, 0.00161742), (0.493188, 0.468078, 0.526295, 0.510571), (0.000646113, 0.000559993, 0.000147566)),
     ("right_wrist_yaw_joint", "z", (-1.61443, 1.61443), "4010")),
)

# Wrist yaw links without the rubber hand (DFQ URDF): (mass, com, (ixx, iyy, izz, ixy, ixz, iyz)).
_WRIST_YAW_NO_RUBBER_HAND = {
    "left_wrist_yaw_link": (0.08457647, (0.02200381568, 0.00049485096, 0.00053861123),
                            (4.929128828e-05, 5.973338134e-05, 3.928083826e-05, -4.5735494e-07, 4.45867591e-06, 4.3217198e-07)),
    "right_wrist_yaw_link": (0.08457647, (0.02200381568, -0.00049485096, 0.00053861123),
                             (4.929128828e-05, 5.973338134e-05, 3.928083826e-05, 4.5735494e-07, 4.45867591e-06, -4.3217198e-07)),
}


def _capsule(name, radius, start, end):
    return GeomSpec(name, "capsule", (radius,), fromto=(*start, *end))


# Collision primitives and sites of the left/centre links; right links get the same with y negated.
_GEOMS = {
    "pelvis": (GeomSpec("pelvis_collision", "box", (0.06, 0.06, 0.06), pos=(0.0, 0.0, -0.09)),),
    "left_hip_yaw_link": (_capsule("left_thigh", 0.05, (0.005, 0.0, 0.02), (-0.07, 0.0, -0.175)),),
    "left_knee_link": (_capsule("left_shin", 0.042, (0.008, 0.0, -0.03), (0.005, 0.0, -0.25)),),
    "left_ankle_roll_link": (GeomSpec("left_foot", "box", (0.1041, 0.0378, 0.01), pos=(0.0383, 0.0, -0.0254)),),
    "torso_link": (
        GeomSpec("torso_collision", "box", (0.07, 0.09, 0.14), pos=(0.008, 0.0, 0.15)),
        GeomSpec("head_collision", "sphere", (0.075,), pos=(0.006, 0.0, 0.41)),
    ),
    "left_shoulder_yaw_link": (_capsule("left_upper_arm", 0.035, (0.0, 0.0, 0.06), (0.012, 0.0, -0.07)),),
    "left_elbow_link": (_capsule("left_forearm", 0.03, (0.0, 0.0, 0.0), (0.11, 0.00208, -0.011)),),
    "left_wrist_pitch_link": (_capsule("left_wrist", 0.028, (0.0, 0.0, 0.0), (0.04, 0.0, 0.0)),),
}
_SITES = {
    "pelvis": (SiteSpec("imu_in_pelvis", (0.04525, 0.0, -0.08339)),),
    "torso_link": (SiteSpec("imu_in_torso", (-0.03959, -0.00224, 0.14792)), SiteSpec("head", (0.0052, 0.0, 0.4866))),
    "left_ankle_roll_link": (SiteSpec("left_toe", (0.1424, 0.0, -0.0354)),),  # front edge of the sole
}
_DARK = (0.2, 0.2, 0.2, 1.0)
_EXTRA_MESHES = {
    "pelvis": (VisualMesh("pelvis.STL", rgba=_DARK), VisualMesh("pelvis_contour_link.STL")),
    "waist_yaw_link": (VisualMesh("waist_yaw_link_rev_1_0.STL"),),
    "waist_roll_link": (VisualMesh("waist_roll_link_rev_1_0.STL"),),
    "torso_link": (
        VisualMesh("torso_link_rev_1_0.STL"),
        VisualMesh("logo_link.STL", pos=(0.0039635, 0.0, -0.044), rgba=_DARK),
        VisualMesh("head_link.STL", pos=(0.0039635, 0.0, -0.044), rgba=_DARK),
    ),
}

# Body pairs (not parent/child) whose primitives overlap by construction; excluded when self-collision is on.
# Contacts inside one hand are excluded too (see _intra_hand_pairs).
CONTACT_EXCLUDES = (
    ("pelvis", "left_hip_yaw_link"),
    ("pelvis", "right_hip_yaw_link"),
    ("pelvis", "torso_link"),
    ("left_knee_link", "left_ankle_roll_link"),
    ("right_knee_link", "right_ankle_roll_link"),
    ("left_elbow_link", "left_wrist_pitch_link"),
    ("right_elbow_link", "right_wrist_pitch_link"),
)


def _mirror_geom(g: GeomSpec) -> GeomSpec:
    x, y, z = g.pos
    fromto = None if g.fromto is None else (g.fromto[0], -g.fromto[1], g.fromto[2], g.fromto[3], -g.fromto[4], g.fromto[5])
    return GeomSpec(g.name.replace("left_", "right_"), g.type, g.size, pos=(x, -y, z), fromto=fromto)


def _left_key(name: str) -> str:
    return name.replace("right_", "left_", 1) if name.startswith("right_") else name


def _g1_body(row) -> BodySpec:
    name, parent, pos, quat, (mass, com, iquat, diag), joint = row
    inertial = Inertial(mass=mass, com=com, diag=diag, quat_wxyz=iquat)
    if name in _WRIST_YAW_NO_RUBBER_HAND:
        mass, com, full = _WRIST_YAW_NO_RUBBER_HAND[name]
        inertial = Inertial(mass=mass, com=com, full=full)
    joint_spec = None
    if joint is not None:
        jname, axis, limits, motor = joint
        m = MOTOR_CLASSES[motor]
        joint_spec = JointSpec(jname, _AXES[axis], limits, effort=m.effort, velocity=m.velocity, armature=m.armature)
    key = _left_key(name)
    mirrored = key != name
    geoms = tuple(_mirror_geom(g) if mirrored else g for g in _GEOMS.get(key, ()))
    sites = tuple(
        SiteSpec(s.name.replace("left_", "right_"), (s.pos[0], -s.pos[1], s.pos[2])) if mirrored else s
        for s in _SITES.get(key, ())
    )
    dark = any(k in name for k in ("pelvis", "hip_pitch", "ankle_roll"))
    meshes = _EXTRA_MESHES.get(name, (VisualMesh(f"{name}.STL", rgba=_DARK if dark else (0.7, 0.7, 0.7, 1.0)),))
    return BodySpec(name, parent, pos, quat, inertial, joint_spec, geoms, sites, meshes)


def _depth_first(bodies: list[BodySpec]) -> tuple[BodySpec, ...]:
    children: dict[str, list[BodySpec]] = {}
    for b in bodies:
        children.setdefault(b.parent, []).append(b)
    ordered: list[BodySpec] = []

    def visit(parent: str) -> None:
        for child in children.get(parent, []):
            ordered.append(child)
            visit(child.name)

    visit("world")
    if len(ordered) != len(bodies):
        raise ValueError("robot description: some bodies are not connected to the floating base")
    return tuple(ordered)


def _intra_hand_pairs(bodies: list[BodySpec], prefix: str) -> tuple[tuple[str, str], ...]:
    """All body pairs within one hand. The Inspire linkage keeps its own fingers and palm apart (a closed fist
    is a valid pose), but our fitted capsules overlap there by a few mm and would jam the fingers."""
    names = [b.name for b in bodies if b.name.startswith(prefix) and b.geoms]
    return tuple((a, b) for i, a in enumerate(names) for b in names[i + 1 :])


def g1_inspire() -> RobotDescription:
    """G1 29-DoF + left and right Inspire DFQ hands (rubber hands removed), depth-first body order."""
    bodies = [_g1_body(row) for row in _G1_LINKS] + list(left_hand()) + list(right_hand())
    return RobotDescription(
        name="g1_inspire",
        base_joint="floating_base_joint",
        bodies=_depth_first(bodies),
        contact_excludes=CONTACT_EXCLUDES + _intra_hand_pairs(bodies, "L_") + _intra_hand_pairs(bodies, "R_"),
    )

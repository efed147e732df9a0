"""Inspire RH56DFQ hands as mounted on the G1 (left and right), as plain data.

Kinematics and mass properties: Unitree's `g1_29dof_rev_1_0_with_inspire_hand_DFQ.urdf` (unitree_ros), which
also gives the joint ranges, the mimic couplings and the wrist mount. Fingertip points: the `*_tip` links of
xr_teleoperate's `inspire_hand_left/right.urdf`. Collision capsules/boxes were fitted by us to the DFQ meshes.
The right hand is listed explicitly (not mirrored in code) because Unitree's right-hand numbers are not an
exact mirror of the left (e.g. the index intermediate offset).

Joint frames are URDF origins (xyz + rpy) converted once with `rpy_to_quat_wxyz`.
"""

from __future__ import annotations

from robot_hoi.embodiment.spec_types import (
    BodySpec,
    GeomSpec,
    Inertial,
    JointSpec,
    Mimic,
    SiteSpec,
    VisualMesh,
    rpy_to_quat_wxyz,
)

# Finger drive dynamics (Unitree's URDF has placeholders only: effort 1, velocity 0.5). Each actuated finger joint
# gets the reflected inertia and the back-drive friction of a lead-screw linear actuator as armature and joint
# damping. Joint damping is integrated implicitly, so the position servo (kp 3, kd 0.05 in the YAML) stays
# stable at the 4.8 ms physics step even while its force is clipped at the effort limit; putting the damping in
# the actuator's kv instead makes a force-limited finger chatter. Result: a no-load full stroke reaches 95 % in
# ~0.48 s (fingers) / ~0.3 s (thumb); the hardware needs ~0.6 s at SPEED 1000 (inspire_protocol.md).
FINGER_EFFORT = 1.0  # N·m
FINGER_VELOCITY = 0.5  # rad/s, Unitree URDF value (informational; MuJoCo does not use it)
ACTUATED_ARMATURE = 5.0e-4  # kg·m²
PASSIVE_ARMATURE = 1.0e-4  # kg·m², keeps the equality-coupled joints well conditioned
FINGER_DAMPING = 0.25  # N·m·s/rad, actuated joints only (passive joints follow through the coupling)

# (link, parent, xyz, rpy, (mass, com, (ixx, iyy, izz, ixy, ixz, iyz)), joint | None)
# joint = (name, axis, (lower, upper), (driver, multiplier) | None)
_LEFT = (
    ("L_hand_base_link", "left_wrist_yaw_link", (0.0415, 0.0, 0.0), (0.0, 0.0, 1.5707963267948966),
     (0.14143, (-0.002551, -0.066047, -0.0019357), (0.0001234, 8.3835e-05, 7.7231e-05, 2.1995e-06, -1.7694e-06, 1.5968e-06)),
     None),
    ("L_thumb_proximal_base", "L_hand_base_link", (-0.01696, -0.0691, 0.02045), (1.5708, -1.5708, 0.0),
     (0.0018869, (0.0048817, 0.00038782, -0.00722), (5.5158e-08, 8.2164e-08, 6.7434e-08, -1.1803e-08, -4.6743e-09, -1.3521e-09)),
     ("L_thumb_proximal_yaw_joint", (0.0, 0.0, 1.0), (-0.1, 1.3), None)),
    ("L_thumb_proximal", "L_thumb_proximal_base", (0.0099867, 0.0098242, -0.0089), (-1.5708, 0.0, 0.16939),
     (0.0066101, (0.021936, -0.01279, -0.0080386), (1.5693e-06, 1.7356e-06, 2.787e-06, 7.8339e-07, 8.5959e-10, 1.0378e-09)),
     ("L_thumb_proximal_pitch_joint", (0.0, 0.0, -1.0), (-0.1, 0.6), None)),
    ("L_thumb_intermediate", "L_thumb_proximal", (0.04407, -0.034553, -0.0008), (0.0, 0.0, 0.0),
     (0.0037844, (0.0095531, 0.0016282, -0.0072002), (3.6981e-07, 3.2395e-07, 4.6532e-07, 9.8603e-08, -2.8173e-12, -2.8028e-12)),
     ("L_thumb_intermediate_joint", (0.0, 0.0, -1.0), (0.0, 0.8), ("L_thumb_proximal_pitch_joint", 1.6))),
    ("L_thumb_distal", "L_thumb_intermediate", (0.020248, -0.010156, -0.0012), (0.0, 0.0, 0.0),
     (0.003344, (0.0092888, -0.004953, -0.0060033), (1.3632e-07, 1.4052e-07, 2.0026e-07, 5.6787e-08, -9.1939e-11, 1.2145e-10)),
     ("L_thumb_distal_joint", (0.0, 0.0, -1.0), (0.0, 1.2), ("L_thumb_proximal_pitch_joint", 2.4))),
    ("L_index_proximal", "L_hand_base_link", (0.00028533, -0.13653, 0.032268), (-0.034907, 0.0, 0.0),
     (0.0042405, (0.0012971, -0.011934, -0.0059998), (6.6215e-07, 2.1167e-07, 6.9402e-07, 1.8442e-08, 1.3746e-12, -1.4773e-11)),
     ("L_index_proximal_joint", (0.0, 0.0, -1.0), (0.0, 1.7), None)),
    ("L_index_intermediate", "L_index_proximal", (-0.0024229, -0.032041, -0.001), (0.0, 0.0, 0.0),
     (0.0045682, (0.0021753, -0.019567, -0.005), (7.6284e-07, 9.4308e-08, 7.8176e-07, -8.063e-08, 3.6797e-13, 1.5743e-13)),
     ("L_index_intermediate_joint", (0.0, 0.0, -1.0), (0.0, 1.7), ("L_index_proximal_joint", 1.0))),
    ("L_middle_proximal", "L_hand_base_link", (0.00028533, -0.1371, 0.01295), (0.0, 0.0, 0.0),
     (0.0042405, (0.0012971, -0.011934, -0.0059999), (6.6215e-07, 2.1167e-07, 6.9402e-07, 1.8442e-08, 1.2299e-12, -1.4484e-11)),
     ("L_middle_proximal_joint", (0.0, 0.0, -1.0), (0.0, 1.7), None)),
    ("L_middle_intermediate", "L_middle_proximal", (-0.0024229, -0.032041, -0.001), (0.0, 0.0, 0.0),
     (0.0050397, (0.001921, -0.020796, -0.0049999), (9.5823e-07, 1.0646e-07, 9.8385e-07, -1.1425e-07, -2.4186e-12, 3.6974e-12)),
     ("L_middle_intermediate_joint", (0.0, 0.0, -1.0), (0.0, 1.7), ("L_middle_proximal_joint", 1.0))),
    ("L_ring_proximal", "L_hand_base_link", (0.00028533, -0.13691, -0.0062872), (0.05236, 0.0, 0.0),
     (0.0042405, (0.0012971, -0.011934, -0.0059999), (6.6215e-07, 2.1167e-07, 6.9402e-07, 1.8442e-08, 9.6052e-13, -1.4124e-11)),
     ("L_ring_proximal_joint", (0.0, 0.0, -1.0), (0.0, 1.7), None)),
    ("L_ring_intermediate", "L_ring_proximal", (-0.0024229, -0.032041, -0.001), (0.0, 0.0, 0.0),
     (0.0045682, (0.0021753, -0.019567, -0.005), (7.6285e-07, 9.4308e-08, 7.8176e-07, -8.0631e-08, 3.3472e-14, -4.4773e-13)),
     ("L_ring_intermediate_joint", (0.0, 0.0, -1.0), (0.0, 1.7), ("L_ring_proximal_joint", 1.0))),
    ("L_pinky_proximal", "L_hand_base_link", (0.00028533, -0.13571, -0.025488), (0.10472, 0.0, 0.0),
     (0.0042405, (0.0012971, -0.011934, -0.0059999), (6.6215e-07, 2.1167e-07, 6.9402e-07, 1.8442e-08, 1.0279e-12, -1.4277e-11)),
     ("L_pinky_proximal_joint", (0.0, 0.0, -1.0), (0.0, 1.7), None)),
    ("L_pinky_intermediate", "L_pinky_proximal", (-0.0024229, -0.032041, -0.001), (0.0, 0.0, 0.0),
     (0.0036036, (0.0024788, -0.016208, -0.0050001), (4.3923e-07, 7.0315e-08, 4.4881e-07, -4.1355e-08, 1.2263e-12, 3.1311e-12)),
     ("L_pinky_intermediate_joint", (0.0, 0.0, -1.0), (0.0, 1.7), ("L_pinky_proximal_joint", 1.0))),
)

_RIGHT = (
    ("R_hand_base_link", "right_wrist_yaw_link", (0.0415, 0.0, 0.0), (3.141592653589793, 0.0, -1.5707963267948966),
     (0.14143, (-0.0025264, -0.066047, 0.0019598), (0.00012281, 8.3832e-05, 7.6663e-05, 2.1711e-06, 1.7709e-06, -1.6551e-06)),
     None),
    ("R_thumb_proximal_base", "R_hand_base_link", (-0.01696, -0.0691, -0.02045), (1.5708, -1.5708, 0.0),
     (0.0018869, (-0.0048064, 0.0009382, -0.00757), (5.816e-08, 7.9161e-08, 6.7433e-08, 1.4539e-08, 4.491e-09, -1.8727e-09)),
     ("R_thumb_proximal_yaw_joint", (0.0, 0.0, -1.0), (-0.1, 1.3), None)),
    ("R_thumb_proximal", "R_thumb_proximal_base", (-0.0088099, 0.010892, -0.00925), (1.5708, 0.0, 2.8587),
     (0.0066075, (0.021932, 0.012785, -0.0080386), (1.5686e-06, 1.7353e-06, 2.786e-06, -7.8296e-07, 8.9143e-10, -1.0191e-09)),
     ("R_thumb_proximal_pitch_joint", (0.0, 0.0, 1.0), (-0.1, 0.6), None)),
    ("R_thumb_intermediate", "R_thumb_proximal", (0.04407, 0.034553, -0.0008), (0.0, 0.0, 0.0),
     (0.0037847, (0.0095544, -0.0016282, -0.0071997), (3.6981e-07, 3.2394e-07, 4.6531e-07, -9.8581e-08, -4.7469e-12, 1.0939e-12)),
     ("R_thumb_intermediate_joint", (0.0, 0.0, 1.0), (0.0, 0.8), ("R_thumb_proximal_pitch_joint", 1.6))),
    ("R_thumb_distal", "R_thumb_intermediate", (0.020248, 0.010156, -0.0012), (0.0, 0.0, 0.0),
     (0.0033441, (0.0092888, 0.0049529, -0.0060033), (1.3632e-07, 1.4052e-07, 2.0026e-07, -5.6788e-08, -9.2764e-11, -1.2283e-10)),
     ("R_thumb_distal_joint", (0.0, 0.0, 1.0), (0.0, 1.2), ("R_thumb_proximal_pitch_joint", 2.4))),
    ("R_index_proximal", "R_hand_base_link", (0.00028533, -0.13653, -0.032268), (-3.1067, 0.0, 0.0),
     (0.0042403, (0.0012259, 0.011942, -0.0060001), (6.6232e-07, 2.1146e-07, 6.9398e-07, -1.5775e-08, 1.8515e-12, -5.0828e-12)),
     ("R_index_proximal_joint", (0.0, 0.0, 1.0), (0.0, 1.7), None)),
    ("R_index_intermediate", "R_index_proximal", (-0.0026138, 0.032026, -0.001), (0.0, 0.0, 0.0),
     (0.0045683, (0.0019697, 0.019589, -0.005), (7.6111e-07, 9.6076e-08, 7.8179e-07, 8.7637e-08, -3.7751e-13, 9.9444e-13)),
     ("R_index_intermediate_joint", (0.0, 0.0, 1.0), (0.0, 1.7), ("R_index_proximal_joint", 1.0))),
    ("R_middle_proximal", "R_hand_base_link", (0.00028533, -0.1371, -0.01295), (-3.1416, 0.0, 0.0),
     (0.0042403, (0.001297, 0.011934, -0.0060001), (6.6211e-07, 2.1167e-07, 6.9397e-07, -1.8461e-08, 1.8002e-12, -6.6808e-12)),
     ("R_middle_proximal_joint", (0.0, 0.0, 1.0), (0.0, 1.7), None)),
    ("R_middle_intermediate", "R_middle_proximal", (-0.0024229, 0.032041, -0.001), (0.0, 0.0, 0.0),
     (0.0050396, (0.001921, 0.020796, -0.005), (9.5822e-07, 1.0646e-07, 9.8384e-07, 1.1425e-07, -2.4791e-12, 5.9173e-12)),
     ("R_middle_intermediate_joint", (0.0, 0.0, 1.0), (0.0, 1.7), ("R_middle_proximal_joint", 1.0))),
    ("R_ring_proximal", "R_hand_base_link", (0.00028533, -0.13691, 0.0062872), (3.0892, 0.0, 0.0),
     (0.0042403, (0.001297, 0.011934, -0.0060002), (6.6211e-07, 2.1167e-07, 6.9397e-07, -1.8461e-08, 1.5793e-12, -6.6868e-12)),
     ("R_ring_proximal_joint", (0.0, 0.0, 1.0), (0.0, 1.7), None)),
    ("R_ring_intermediate", "R_ring_proximal", (-0.0024229, 0.032041, -0.001), (0.0, 0.0, 0.0),
     (0.0045683, (0.0021753, 0.019567, -0.005), (7.6286e-07, 9.431e-08, 7.8177e-07, 8.0635e-08, -6.1562e-13, 5.8619e-13)),
     ("R_ring_intermediate_joint", (0.0, 0.0, 1.0), (0.0, 1.7), ("R_ring_proximal_joint", 1.0))),
    ("R_pinky_proximal", "R_hand_base_link", (0.00028533, -0.13571, 0.025488), (3.0369, 0.0, 0.0),
     (0.0042403, (0.001297, 0.011934, -0.0060001), (6.6211e-07, 2.1167e-07, 6.9397e-07, -1.8461e-08, 1.6907e-12, -6.9334e-12)),
     ("R_pinky_proximal_joint", (0.0, 0.0, 1.0), (0.0, 1.7), None)),
    ("R_pinky_intermediate", "R_pinky_proximal", (-0.0024229, 0.032041, -0.001), (0.0, 0.0, 0.0),
     (0.0035996, (0.0024748, 0.016203, -0.0050031), (4.3913e-07, 7.0247e-08, 4.4867e-07, 4.1418e-08, 3.7168e-11, 5.8613e-11)),
     ("R_pinky_intermediate_joint", (0.0, 0.0, 1.0), (0.0, 1.7), ("R_pinky_proximal_joint", 1.0))),
)

# Fingertip points (xr_teleoperate *_tip links) on the left hand; the right hand's are the same with y negated.
_LEFT_TIPS = {
    "L_thumb_distal": ("L_thumb_tip", (0.015, -0.013, -0.004)),
    "L_index_intermediate": ("L_index_tip", (-0.005, -0.04, -0.004)),
    "L_middle_intermediate": ("L_middle_tip", (-0.005, -0.045, -0.004)),
    "L_ring_intermediate": ("L_ring_tip", (-0.002, -0.04, -0.004)),
    "L_pinky_intermediate": ("L_pinky_tip", (-0.002, -0.032, -0.004)),
}

# Collision capsules in each link's own frame for the left hand: link suffix -> (radius, from, to).
# The right fingers' meshes are the left ones mirrored in local y.
_FINGER_CAPSULES = {
    "thumb_proximal": (0.012, (0.006, -0.004, -0.008), (0.042, -0.024, -0.008)),
    "thumb_intermediate": (0.009, (0.0, 0.0, -0.0072), (0.016, -0.004, -0.0072)),
    "thumb_distal": (0.008, (0.002, 0.0, -0.006), (0.013, -0.008, -0.006)),
    "index_proximal": (0.0085, (0.0005, 0.0, -0.006), (0.0005, -0.028, -0.006)),
    "middle_proximal": (0.0085, (0.0005, 0.0, -0.006), (0.0005, -0.028, -0.006)),
    "ring_proximal": (0.0085, (0.0005, 0.0, -0.006), (0.0005, -0.028, -0.006)),
    "pinky_proximal": (0.0085, (0.0005, 0.0, -0.006), (0.0005, -0.028, -0.006)),
    "index_intermediate": (0.0068, (0.0025, -0.001, -0.005), (0.0005, -0.038, -0.005)),
    "middle_intermediate": (0.0068, (0.0025, -0.001, -0.005), (0.0005, -0.042, -0.005)),
    "ring_intermediate": (0.0068, (0.0025, -0.001, -0.005), (0.0005, -0.038, -0.005)),
    "pinky_intermediate": (0.0068, (0.0025, -0.001, -0.005), (0.0005, -0.030, -0.005)),
}
# Palm (hand base) box: palm thickness along x, length along -y (wrist flange to knuckles), width along z.
# The right palm mesh is the left one mirrored in z.
_PALM_HALF = (0.02, 0.068, 0.0405)
_PALM_CENTER_LEFT = (-0.001, -0.07, -0.002)

# Visual meshes (Unitree's STL names) per link suffix, for the optional viewer-only meshes.
_MESH_NUMBER = {
    "thumb_proximal_base": 11, "thumb_proximal": 12, "thumb_intermediate": 13, "thumb_distal": 14,
    "index_proximal": 15, "index_intermediate": 16, "middle_proximal": 17, "middle_intermediate": 18,
    "ring_proximal": 19, "ring_intermediate": 20, "pinky_proximal": 21, "pinky_intermediate": 22,
}


def _mirror_y(p):
    return (p[0], -p[1], p[2])


def _hand_bodies(rows, side: str) -> tuple[BodySpec, ...]:
    bodies = []
    for link, parent, xyz, rpy, (mass, com, full), joint in rows:
        suffix = link[2:]
        mirror = _mirror_y if side == "R" else (lambda p: p)
        geoms: tuple[GeomSpec, ...] = ()
        sites: tuple[SiteSpec, ...] = ()
        if suffix == "hand_base_link":
            cx, cy, cz = _PALM_CENTER_LEFT
            center = (cx, cy, -cz) if side == "R" else (cx, cy, cz)
            geoms = (GeomSpec(f"{side}_palm", "box", _PALM_HALF, pos=center),)
            mesh = VisualMesh(f"{side}_hand_base_link.STL", rgba=(0.9, 0.9, 0.9, 1.0))
        else:
            radius, start, end = _FINGER_CAPSULES[suffix] if suffix in _FINGER_CAPSULES else (None, None, None)
            if radius is not None:
                geoms = (GeomSpec(f"{link}_collision", "capsule", (radius,), fromto=(*mirror(start), *mirror(end))),)
            mesh = VisualMesh(f"Link{_MESH_NUMBER[suffix]}_{side}.STL", rgba=(0.9, 0.9, 0.9, 1.0))
        left_name = "L_" + suffix
        if left_name in _LEFT_TIPS:
            tip_name, tip_pos = _LEFT_TIPS[left_name]
            sites = (SiteSpec(side + tip_name[1:], mirror(tip_pos)),)
        joint_spec = None
        if joint is not None:
            name, axis, limits, mimic = joint
            joint_spec = JointSpec(
                name=name,
                axis=axis,
                range=limits,
                effort=FINGER_EFFORT,
                velocity=FINGER_VELOCITY,
                armature=PASSIVE_ARMATURE if mimic else ACTUATED_ARMATURE,
                damping=0.0 if mimic else FINGER_DAMPING,
                mimic=Mimic(*mimic) if mimic else None,
            )
        bodies.append(
            BodySpec(
                name=link,
                parent=parent,
                pos=xyz,
                quat_wxyz=rpy_to_quat_wxyz(*rpy),
                inertial=Inertial(mass=mass, com=com, full=full),
                joint=joint_spec,
                geoms=geoms,
                sites=sites,
                meshes=(mesh,),
                rpy=rpy,
            )
        )
    return tuple(bodies)


def left_hand() -> tuple[BodySpec, ...]:
    return _hand_bodies(_LEFT, "L")


def right_hand() -> tuple[BodySpec, ...]:
    return _hand_bodies(_RIGHT, "R")

"""Landmarks: the point on the robot that the IK puts on each human joint of the embodiment's link_map.

The link_map names the robot links that rewards track (e.g. `left_hip_yaw_link` for the human hip, as
InterMimic's G1 setup does), but several of those link origins are not where the matching human joint is: the
G1 hip-yaw and shoulder-yaw frames sit ~12 cm and ~10 cm down the thigh and upper arm, and the `head` site is the
top of the head while the SMPL-X head joint is mid-skull. Solving the IK on those origins drags the whole body
by a constant morphology error. A landmark is (frame, offset): a body or site of the model and a fixed point in
its coordinates, chosen so that it sits where the human joint is on a robot standing like the scaled human.

The G1 numbers come from the model (Unitree rev 1.0 link offsets) and from the reference clips (sub2, sub3,
sub8 scaled by 1.32 / height: hip 0.072 m below the pelvis joint, torso joint 0.088 above it, ankle joint
~0.10 m and toe joint ~0.05 m above the floor, toe 0.10 m ahead of and 0.045 m below the ankle, head joint
~0.44 m from the pelvis). Links not listed, and every fingertip, use their own origin: the hands must put the
real fingertips on the object.
"""

from __future__ import annotations

Landmark = tuple[str, tuple[float, float, float]]

_G1_CENTRE = {
    "pelvis": ("pelvis", (0.0, 0.0, -0.06)),  # the G1 pelvis origin sits high: robot legs are long for its height
    "torso_link": ("torso_link", (0.0, 0.0, -0.016)),  # 0.088 above the pelvis landmark
    "head": ("torso_link", (0.0052, 0.0, 0.40)),  # mid-head, not the top (the site is at z 0.4866)
}
_G1_SIDE = {
    # the human hip joint is a point fixed in the pelvis: on the G1's hip-pitch axis (y +-0.064), 0.072 below the
    # pelvis landmark like the human's (the hip-yaw origin is 0.26 m down, mid-thigh)
    "{s}_hip_yaw_link": ("pelvis", (0.0, 0.064, -0.132)),
    "{s}_shoulder_yaw_link": ("{s}_shoulder_roll_link", (0.0, 0.0, 0.0)),  # the shoulder joint, not mid-arm
    "{s}_ankle_roll_link": ("{s}_ankle_roll_link", (0.0, 0.0, 0.06)),  # human ankle height above the sole
    "{s}_toe": ("{s}_ankle_roll_link", (0.10, 0.0, 0.015)),  # the toe joint (ball of the foot), not the tip
}

def _sided(side: str) -> dict[str, Landmark]:
    sign = 1.0 if side == "left" else -1.0
    return {k.format(s=side): (f.format(s=side), (x, sign * y + 0.0, z)) for k, (f, (x, y, z)) in _G1_SIDE.items()}


LANDMARKS: dict[str, dict[str, Landmark]] = {"g1_inspire": {**_G1_CENTRE, **_sided("left"), **_sided("right")}}


def landmarks_for(embodiment: str, link_names) -> dict[str, Landmark]:
    """The landmarks of an embodiment restricted to its link_map names ({} for an unknown embodiment)."""
    table = LANDMARKS.get(embodiment, {})
    return {name: table[name] for name in link_names if name in table}

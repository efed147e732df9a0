"""A plausible 52-body skeleton of a ~1.75 m adult in the clip format's convention (PHC upright start).

Identity rotations give the T-pose facing +x, left = +y, up = +z. Offsets are each body's position in its
parent's frame (m), rounded from the proportions of the OMOMO subjects scaled to 1.75 m, and mirror-symmetric
(right = left with y negated). Used by the synthetic default clip and to rebuild unusable finger rows.
"""

from __future__ import annotations

import numpy as np

from robot_hoi.data.layout import BODY_INDEX, BODY_NAMES, NUM_BODIES, mirror_body

# Left side and centre line; the right side is mirrored below.
_LEFT_AND_CENTRE = {
    "L_Hip": (-0.020, 0.055, -0.100),
    "L_Knee": (0.000, 0.050, -0.370),
    "L_Ankle": (-0.040, -0.030, -0.410),
    "L_Toe": (0.135, 0.035, -0.055),
    "Torso": (-0.035, 0.000, 0.115),
    "Spine": (0.002, 0.000, 0.160),
    "Chest": (0.020, 0.000, 0.060),
    "Neck": (-0.024, 0.000, 0.163),
    "Head": (0.020, 0.000, 0.143),
    "L_Thorax": (-0.006, 0.040, 0.076),
    "L_Shoulder": (-0.017, 0.122, 0.062),
    "L_Elbow": (-0.036, 0.250, -0.060),
    "L_Wrist": (-0.005, 0.257, 0.013),
    "L_Index1": (0.021, 0.104, -0.010),
    "L_Index2": (0.002, 0.031, -0.012),
    "L_Index3": (-0.003, 0.006, -0.022),
    "L_Middle1": (-0.004, 0.112, -0.007),
    "L_Middle2": (-0.005, 0.027, -0.016),
    "L_Middle3": (-0.002, 0.005, -0.024),
    "L_Pinky1": (-0.046, 0.086, -0.016),
    "L_Pinky2": (-0.005, 0.013, -0.015),
    "L_Pinky3": (0.001, 0.004, -0.019),
    "L_Ring1": (-0.029, 0.100, -0.010),
    "L_Ring2": (-0.001, 0.024, -0.017),
    "L_Ring3": (0.002, 0.004, -0.024),
    "L_Thumb1": (0.027, 0.041, -0.021),
    "L_Thumb2": (0.013, 0.022, -0.018),
    "L_Thumb3": (0.008, 0.024, -0.008),
}

TEMPLATE_HEIGHT_M = 1.75
ANKLE_HEIGHT_M = 0.085  # ankle joint above the floor with the foot flat (toe joint ~3 cm above)

# Where the rest hand meets a flat surface, in the wrist's frame (palm faces -z in the T-pose): the rest hand's
# fingers curl ~5 cm to the palm side, so it rests on its finger pads (finger joints + ~8 mm of flesh).
L_PALM_CENTRE = np.array([0.000, 0.100, -0.059])
R_PALM_CENTRE = L_PALM_CENTRE * np.array([1.0, -1.0, 1.0])


def template_offsets() -> np.ndarray:
    """Bone offsets (52, 3) of the template adult; row 0 (pelvis) is zero."""
    offsets = np.zeros((NUM_BODIES, 3))
    for name, value in _LEFT_AND_CENTRE.items():
        i = BODY_INDEX[name]
        offsets[i] = value
        mirrored = mirror_body(i)
        if mirrored != i:
            offsets[mirrored] = np.array(value) * (1.0, -1.0, 1.0)
    missing = [BODY_NAMES[i] for i in range(1, NUM_BODIES) if not offsets[i].any()]
    assert not missing, missing  # every body but the pelvis has an offset
    return offsets


def leg_lengths(offsets: np.ndarray) -> tuple[float, float]:
    """(thigh, shank) lengths of the left leg."""
    return float(np.linalg.norm(offsets[BODY_INDEX["L_Knee"]])), float(
        np.linalg.norm(offsets[BODY_INDEX["L_Ankle"]])
    )


def standing_pelvis_height(offsets: np.ndarray) -> float:
    """Pelvis height (m) with straight legs under the hips and flat feet (upper bound while standing)."""
    thigh, shank = leg_lengths(offsets)
    hip_drop = -offsets[BODY_INDEX["L_Hip"], 2]
    return hip_drop + thigh + shank + ANKLE_HEIGHT_M

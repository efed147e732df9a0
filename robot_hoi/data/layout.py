"""The InterMimic / InterAct "hoi_data" clip layout, documented once.

One clip is a float32 matrix (T, 591), one row per frame at 30 fps. World frame: z-up, ground at z = 0, metres,
radians. Every quaternion in the file is xyzw (scalar last, scipy's convention).

    columns   size  content
    0:3         3   root (pelvis) position, world; equals body_pos[:, 0]
    3:7         4   root orientation, quaternion xyzw, world; equals body_quat[:, 0]
    7:9         2   unused (always 0)
    9:162     153   51 joints x 3: rotation vector of each non-root body relative to its parent
                    (R.from_rotvec(dof[j-1]) == inv(R_parent(j)) * R_j), bodies 1..51 in BODY_NAMES order
    162:318   156   52 bodies x 3: world positions
    318:321     3   object position (world position of the object mesh's local origin)
    321:325     4   object orientation, quaternion xyzw: world = R(q).apply(p_local) + pos
    325:330     5   unused (always 0)
    330         1   object-contact flag 0/1
    331:383    52   per-body contact label: +1 touches the object, -1 far (> 10 cm), 0 undetermined
    383:591   208   52 bodies x 4: global orientation quaternions xyzw (PHC upright start: identity is the
                    T-pose facing +x, left = +y, up = +z)

Source: ../shared/reference/motions/SOURCES.md (InterMimic `_load_motion`, InterAct `interact2mimic.py`).
"""

from __future__ import annotations

NUM_COLUMNS = 591
NUM_BODIES = 52
NUM_JOINTS = NUM_BODIES - 1  # every body but the root has a 3-DoF joint
CLIP_FPS = 30.0

ROOT_POS = slice(0, 3)
ROOT_QUAT_XYZW = slice(3, 7)
UNUSED_A = slice(7, 9)
DOF_ROTVEC = slice(9, 162)
BODY_POS = slice(162, 318)
OBJECT_POS = slice(318, 321)
OBJECT_QUAT_XYZW = slice(321, 325)
UNUSED_B = slice(325, 330)
CONTACT = 330
BODY_CONTACT = slice(331, 383)
BODY_QUAT_XYZW = slice(383, 591)

# Columns that hold motion (everything but the contact labels): all zero in a physics-corrected clip's frame 0.
KINEMATIC_COLUMN_SLICES = (slice(0, 330), BODY_QUAT_XYZW)

# Stored per-body contact label values.
LABEL_CONTACT = 1
LABEL_FAR = -1
LABEL_UNKNOWN = 0

BODY_NAMES = (
    "Pelvis",
    "L_Hip", "L_Knee", "L_Ankle", "L_Toe",
    "R_Hip", "R_Knee", "R_Ankle", "R_Toe",
    "Torso", "Spine", "Chest", "Neck", "Head",
    "L_Thorax", "L_Shoulder", "L_Elbow", "L_Wrist",
    "L_Index1", "L_Index2", "L_Index3",
    "L_Middle1", "L_Middle2", "L_Middle3",
    "L_Pinky1", "L_Pinky2", "L_Pinky3",
    "L_Ring1", "L_Ring2", "L_Ring3",
    "L_Thumb1", "L_Thumb2", "L_Thumb3",
    "R_Thorax", "R_Shoulder", "R_Elbow", "R_Wrist",
    "R_Index1", "R_Index2", "R_Index3",
    "R_Middle1", "R_Middle2", "R_Middle3",
    "R_Pinky1", "R_Pinky2", "R_Pinky3",
    "R_Ring1", "R_Ring2", "R_Ring3",
    "R_Thumb1", "R_Thumb2", "R_Thumb3",
)  # fmt: skip

BODY_PARENTS = (
    -1,
    0, 1, 2, 3,
    0, 5, 6, 7,
    0, 9, 10, 11, 12,
    11, 14, 15, 16,
    17, 18, 19,
    17, 21, 22,
    17, 24, 25,
    17, 27, 28,
    17, 30, 31,
    11, 33, 34, 35,
    36, 37, 38,
    36, 40, 41,
    36, 43, 44,
    36, 46, 47,
    36, 49, 50,
)  # fmt: skip

BODY_INDEX = {name: i for i, name in enumerate(BODY_NAMES)}

# The 22 SMPL-X body joints (pelvis .. wrists) and the 2 x 15 finger joints.
L_FINGERS = tuple(range(18, 33))
R_FINGERS = tuple(range(37, 52))
FINGERS = L_FINGERS + R_FINGERS
BODY_JOINTS = tuple(i for i in range(NUM_BODIES) if i not in FINGERS)
L_HAND = (BODY_INDEX["L_Wrist"],) + L_FINGERS  # wrist + fingers: one contact unit, as the stored labels are
R_HAND = (BODY_INDEX["R_Wrist"],) + R_FINGERS
HANDS = L_HAND + R_HAND
FEET = tuple(BODY_INDEX[n] for n in ("L_Ankle", "L_Toe", "R_Ankle", "R_Toe"))
L_THUMB = tuple(BODY_INDEX[f"L_Thumb{k}"] for k in (1, 2, 3))
R_THUMB = tuple(BODY_INDEX[f"R_Thumb{k}"] for k in (1, 2, 3))
FINGERTIP_BODIES = tuple(
    BODY_INDEX[f"{s}_{f}3"] for s in "LR" for f in ("Index", "Middle", "Pinky", "Ring", "Thumb")
)

# Subject heights (m) from holosoma_retargeting demo_data/height_dict.pkl (see SOURCES.md).
SUBJECT_HEIGHTS_M = {
    "sub1": 1.664, "sub2": 1.844, "sub3": 1.941, "sub4": 1.790, "sub5": 1.817, "sub6": 1.762,
    "sub7": 1.808, "sub8": 1.845, "sub9": 1.753, "sub10": 1.651, "sub11": 1.767, "sub12": 1.803,
    "sub13": 1.811, "sub14": 1.826, "sub15": 1.685, "sub16": 1.723, "sub17": 1.737,
}  # fmt: skip

# sub8 finger-row bug (InterAct's older OMOMO export, body_pos only). Buggy row r holds SMPL-X joint r + 4 for
# rows 18..32 (18-20 = jaw/eyes) and SMPL-X joint r for rows 37..51; the right thumb is lost. Correct layout:
# rows 18..32 = SMPL-X 25..39 (left hand), rows 37..51 = SMPL-X 40..54 (right hand).
# As (correct rows, buggy rows) pairs, for the rows that can be recovered:
SHIFTED_FINGER_ROW_FIX = (
    (tuple(range(18, 30)), tuple(range(21, 33))),  # left index, middle, pinky, ring
    (tuple(range(30, 33)), tuple(range(37, 40))),  # left thumb
    (tuple(range(37, 49)), tuple(range(40, 52))),  # right index, middle, pinky, ring
)


def mirror_body(index: int) -> int:
    """The same body on the other side (L_* <-> R_*); central bodies map to themselves."""
    name = BODY_NAMES[index]
    if name.startswith("L_"):
        return BODY_INDEX["R_" + name[2:]]
    if name.startswith("R_"):
        return BODY_INDEX["L_" + name[2:]]
    return index

import numpy as np

from robot_hoi.data import layout as L


def test_column_slices_cover_the_591_columns_once():
    parts = [
        L.ROOT_POS,
        L.ROOT_QUAT_XYZW,
        L.UNUSED_A,
        L.DOF_ROTVEC,
        L.BODY_POS,
        L.OBJECT_POS,
        L.OBJECT_QUAT_XYZW,
        L.UNUSED_B,
        slice(L.CONTACT, L.CONTACT + 1),
        L.BODY_CONTACT,
        L.BODY_QUAT_XYZW,
    ]
    covered = np.zeros(L.NUM_COLUMNS, dtype=int)
    for s in parts:
        covered[s] += 1
    assert (covered == 1).all()
    assert L.DOF_ROTVEC.stop - L.DOF_ROTVEC.start == 3 * L.NUM_JOINTS
    assert L.BODY_QUAT_XYZW.stop - L.BODY_QUAT_XYZW.start == 4 * L.NUM_BODIES


def test_skeleton_tree_is_ordered_and_named():
    assert len(L.BODY_NAMES) == len(L.BODY_PARENTS) == 52
    assert L.BODY_PARENTS[0] == -1
    assert all(0 <= p < j for j, p in enumerate(L.BODY_PARENTS) if j)
    assert L.BODY_PARENTS[L.BODY_INDEX["L_Wrist"]] == L.BODY_INDEX["L_Elbow"]
    assert L.BODY_PARENTS[L.BODY_INDEX["R_Thorax"]] == L.BODY_INDEX["Chest"]
    assert all(L.BODY_PARENTS[j] in (17, 36) or L.BODY_PARENTS[j] in L.FINGERS for j in L.FINGERS)
    assert len(L.BODY_JOINTS) == 22 and len(L.FINGERS) == 30


def test_mirror_pairs_left_and_right():
    for j in range(52):
        m = L.mirror_body(j)
        assert L.mirror_body(m) == j
        assert L.BODY_NAMES[j][2:] == L.BODY_NAMES[m][2:] or j == m


def test_finger_fix_table_moves_every_recoverable_row():
    correct = [r for rows, _ in L.SHIFTED_FINGER_ROW_FIX for r in rows]
    buggy = [r for _, rows in L.SHIFTED_FINGER_ROW_FIX for r in rows]
    assert sorted(correct + list(L.R_THUMB)) == sorted(L.FINGERS)
    assert len(set(buggy)) == len(buggy) == 27


def test_subject_heights_match_sources():
    assert L.SUBJECT_HEIGHTS_M["sub3"] == 1.941 and L.SUBJECT_HEIGHTS_M["sub8"] == 1.845
    assert len(L.SUBJECT_HEIGHTS_M) == 17

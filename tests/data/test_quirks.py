import numpy as np
from scipy.spatial.transform import Rotation

from robot_hoi.data.kinematics import make_quaternions_continuous
from robot_hoi.data.layout import FINGERS, L_FINGERS, R_THUMB, SHIFTED_FINGER_ROW_FIX
from robot_hoi.data.quirks import (
    finger_offset_spread,
    fix_quaternion_signs,
    fix_shifted_finger_rows,
    leading_placeholder_frames,
)


def test_sign_flips_become_continuous_without_changing_rotations():
    rng = np.random.default_rng(1)
    angles = np.linspace(0.0, 6.0, 120)
    q = Rotation.from_rotvec(angles[:, None] * np.array([0.0, 0.6, 0.8])).as_quat()
    flipped = q * np.where(rng.random(120) < 0.3, -1.0, 1.0)[:, None]
    fixed, count = make_quaternions_continuous(flipped)
    assert count > 10
    assert (np.sum(fixed[1:] * fixed[:-1], axis=-1) > 0).all()
    np.testing.assert_allclose(np.abs(np.sum(fixed * q, axis=-1)), 1.0, atol=1e-12)  # same rotations


def test_sign_fix_works_per_body_stream(lift_clip):
    clip = lift_clip.copy()
    clip.body_quat_xyzw[50:, 7] *= -1.0
    clip.object_quat_xyzw[10:20] *= -1.0
    notes = fix_quaternion_signs(clip)
    assert notes == ["fixed: 3 quaternion sign flips (q vs -q) made continuous"]
    assert (np.sum(clip.body_quat_xyzw[1:] * clip.body_quat_xyzw[:-1], axis=-1) > 0).all()


def test_placeholder_frames_are_counted():
    raw = np.ones((5, 591))
    raw[:2, :330] = 0.0
    raw[:2, 383:] = 0.0
    raw[:2, 331:383] = 1.0  # labels may be set in the placeholder
    assert leading_placeholder_frames(raw) == 2
    raw[1, 0] = 0.5
    assert leading_placeholder_frames(raw) == 1


def _shift_like_sub8(body_pos):
    buggy = body_pos.copy()
    for correct, wrong in SHIFTED_FINGER_ROW_FIX:
        buggy[:, list(wrong)] = body_pos[:, list(correct)]
    buggy[:, 18:21] = body_pos[:, 13:14] + 0.05  # jaw / eyes near the head
    return buggy


def test_sub8_style_shift_is_undone(lift_clip):
    buggy = _shift_like_sub8(lift_clip.body_pos)
    assert finger_offset_spread(buggy, lift_clip.body_quat_xyzw) > 0.05
    fixed, notes = fix_shifted_finger_rows(buggy, lift_clip.body_quat_xyzw)
    assert "shifted by 3 SMPL-X joints" in notes[0]
    recovered = [j for j in FINGERS if j not in R_THUMB]
    np.testing.assert_array_equal(fixed[:, recovered], lift_clip.body_pos[:, recovered])
    # the template skeleton is mirror-symmetric, so the rebuilt right thumb is exact up to rounding
    np.testing.assert_allclose(fixed[:, list(R_THUMB)], lift_clip.body_pos[:, list(R_THUMB)], atol=1e-9)


def test_unexplained_finger_mess_is_rebuilt_from_the_template(lift_clip):
    messy = lift_clip.body_pos.copy()
    rng = np.random.default_rng(0)
    messy[:, list(L_FINGERS)] += rng.normal(0.0, 0.05, messy[:, list(L_FINGERS)].shape)
    fixed, notes = fix_shifted_finger_rows(messy, lift_clip.body_quat_xyzw)
    assert "unreliable" in notes[0]
    assert finger_offset_spread(fixed, lift_clip.body_quat_xyzw) < 1e-9
    np.testing.assert_allclose(fixed, lift_clip.body_pos, atol=1e-9)  # the synthetic skeleton is the template


def test_noise_alone_does_not_trigger_the_finger_fix(lift_clip):
    noisy = lift_clip.body_pos + np.random.default_rng(2).normal(0.0, 0.01, lift_clip.body_pos.shape)
    fixed, notes = fix_shifted_finger_rows(noisy, lift_clip.body_quat_xyzw)
    assert notes == [] and fixed is noisy

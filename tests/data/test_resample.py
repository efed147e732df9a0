import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robot_hoi.data.kinematics import rotvec_mismatch
from robot_hoi.data.resample import (
    fill_missing_frames,
    interpolate_linear,
    interpolate_quats,
    resample_clip,
    resample_times,
)
from robot_hoi.data.validate import validate_clip


def test_times_cover_the_same_span_for_non_integer_ratios():
    np.testing.assert_allclose(resample_times(3, 10.0, 25.0), [0.0, 0.04, 0.08, 0.12, 0.16, 0.20])
    assert len(resample_times(31, 30.0, 50.0)) == 51  # 1.0 s at 50 Hz
    assert len(resample_times(30, 30.0, 50.0)) == 49  # 0.9667 s: last sample at 0.96 s


def test_positions_are_linear_between_frames():
    values = np.array([[0.0], [1.0], [4.0]])
    out = interpolate_linear(np.array([0.0, 0.1, 0.2]), values, resample_times(3, 10.0, 25.0))
    np.testing.assert_allclose(out[:, 0], [0.0, 0.4, 0.8, 1.6, 2.8, 4.0], atol=1e-12)


def test_rotations_are_slerped():
    angles = np.array([0.0, 0.2, 0.6])  # about z, at 10 fps
    q = Rotation.from_rotvec(angles[:, None] * [0.0, 0.0, 1.0]).as_quat()
    out = interpolate_quats(np.array([0.0, 0.1, 0.2]), q, resample_times(3, 10.0, 25.0))
    got = Rotation.from_quat(out).as_rotvec()[:, 2]
    np.testing.assert_allclose(got, [0.0, 0.08, 0.16, 0.28, 0.44, 0.6], atol=1e-12)


def test_slerp_takes_the_short_way_even_across_sign_flips():
    q0 = Rotation.from_rotvec([0.0, 0.0, 3.0]).as_quat()
    q1 = -Rotation.from_rotvec([0.0, 0.0, -3.0]).as_quat()  # 0.283 rad away through +-pi, stored with a flip
    mid = interpolate_quats(np.array([0.0, 1.0]), np.stack([q0, q1]), np.array([0.5]))
    assert Rotation.from_quat(mid).magnitude()[0] == pytest.approx(np.pi, abs=1e-9)


def test_clip_resampled_to_50_hz_stays_valid(lift_clip):
    out = resample_clip(lift_clip, 50.0)
    assert out.fps == 50.0 and out.num_frames == len(resample_times(lift_clip.num_frames, 30.0, 50.0))
    validate_clip(out, path="resampled")
    assert rotvec_mismatch(out.dof_rotvec, out.body_quat_xyzw)[0] < 1e-9
    # frame 5 at 50 Hz is t = 0.1 s = frame 3 at 30 Hz exactly
    np.testing.assert_allclose(out.body_pos[5], lift_clip.body_pos[3], atol=1e-12)
    np.testing.assert_array_equal(out.contact[5], lift_clip.contact[3])
    assert out.duration == pytest.approx(lift_clip.duration, abs=0.05)
    assert "resampled from 30 to 50 fps" in out.problems[-1]


def test_missing_frames_are_filled_by_interpolation(lift_clip):
    clip = lift_clip.copy()
    clip.body_pos[100:103] = np.nan
    clip.body_quat_xyzw[100:103] = np.nan
    notes = fill_missing_frames(clip)
    assert notes and "3 frame(s)" in notes[0] and "100-102" in notes[0]
    validate_clip(clip, path="filled")
    # the synthetic motion is smooth: bridging a 4-frame gap (during the lift) lands within 2 cm of the truth
    assert np.abs(clip.body_pos[100:103] - lift_clip.body_pos[100:103]).max() < 0.02

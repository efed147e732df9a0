import json

import numpy as np
import pytest

from robot_hoi.data.clip import FRAME_ARRAYS, load_clip, sidecar_path
from robot_hoi.errors import DataError, UserError


def test_npz_round_trip_is_exact(lift_clip, tmp_path):
    path = lift_clip.save(tmp_path / "clip.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "clip.json",
        "clip.npz",
    ]  # no temp files left behind
    back = load_clip(path)
    for key in FRAME_ARRAYS:
        a, b = getattr(lift_clip, key), getattr(back, key)
        assert a.dtype == b.dtype, key
        np.testing.assert_array_equal(a, b, err_msg=key)
    for key in (
        "name",
        "fps",
        "subject",
        "subject_height_m",
        "height_source",
        "object_name",
        "source",
        "license",
    ):
        assert getattr(back, key) == getattr(lift_clip, key), key
    np.testing.assert_array_equal(back.object.vertices, lift_clip.object.vertices)
    np.testing.assert_array_equal(back.object.faces, lift_clip.object.faces)
    np.testing.assert_array_equal(back.object.sample_points, lift_clip.object.sample_points)
    assert back.object.mass_kg == lift_clip.object.mass_kg
    assert back.problems == lift_clip.problems == []
    meta = json.loads(sidecar_path(path).read_text())
    assert meta["format_version"] == 1 and meta["quaternion_convention"] == "xyzw"


def test_npz_holds_only_numeric_arrays(lift_clip, tmp_path):
    path = lift_clip.save(tmp_path / "clip.npz")
    with np.load(path, allow_pickle=False) as npz:
        assert all(npz[k].dtype != object for k in npz.files)


def test_save_wants_npz_suffix(lift_clip, tmp_path):
    with pytest.raises(UserError, match="npz"):
        lift_clip.save(tmp_path / "clip.pt")


def test_missing_sidecar_is_named(lift_clip, tmp_path):
    path = lift_clip.save(tmp_path / "clip.npz")
    sidecar_path(path).unlink()
    with pytest.raises(DataError, match=r"clip\.npz.*clip\.json"):
        load_clip(path)


def test_object_arrays_are_never_unpickled(lift_clip, tmp_path):
    path = lift_clip.save(tmp_path / "clip.npz")
    arrays = dict(np.load(path))
    arrays["body_pos"] = np.array([object()] * 3, dtype=object)
    np.savez(path, **arrays)  # pickles the object array
    with pytest.raises(DataError, match="clip.npz"):
        load_clip(path)


def test_wrong_shape_and_truncation_are_named(lift_clip, tmp_path):
    path = lift_clip.save(tmp_path / "clip.npz")
    arrays = dict(np.load(path))
    arrays["body_quat_xyzw"] = arrays["body_quat_xyzw"][:, :51]
    np.savez(path, **arrays)
    with pytest.raises(DataError, match=r"clip\.npz.*body_quat_xyzw.*shape"):
        load_clip(path)
    lift_clip.save(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])
    with pytest.raises(DataError, match=r"clip\.npz.*not a readable npz"):
        load_clip(path)


def test_unknown_suffix_and_missing_file(tmp_path):
    (tmp_path / "clip.csv").write_text("1,2,3")
    with pytest.raises(UserError, match="unknown clip format"):
        load_clip(tmp_path / "clip.csv")
    with pytest.raises(DataError, match="not found"):
        load_clip(tmp_path / "nope.pt")


def test_select_frames_and_copy_are_independent(lift_clip):
    part = lift_clip.select_frames(slice(10, 20))
    assert part.num_frames == 10 and part.duration == pytest.approx(10 / 30)
    part.body_pos[:] = 0
    assert lift_clip.body_pos[10:20].any()

"""Corrupted copies of a reference clip fail with one clear message naming the file (skipped without ../shared)."""

import numpy as np
import pytest
import torch

from robot_hoi.cli import main
from robot_hoi.data.clip import load_clip
from robot_hoi.data.intermimic import read_intermimic_matrix
from robot_hoi.errors import DataError

pytestmark = pytest.mark.shared
NAME = "sub3_largebox_003"


@pytest.fixture()
def raw(motions):
    return np.array(read_intermimic_matrix(motions / "clips" / f"{NAME}.pt"))


def _write(tmp_path, matrix) -> str:
    path = tmp_path / f"{NAME}.pt"
    torch.save(torch.from_numpy(np.ascontiguousarray(matrix, dtype=np.float32)), path)
    return str(path)


def _fails(path, motions, match):
    with pytest.raises(DataError, match=match) as info:
        load_clip(path, objects_dir=motions / "objects")
    assert str(path) in str(info.value)
    return str(info.value)


def test_truncated_zip(motions, tmp_path):
    data = (motions / "clips" / f"{NAME}.pt").read_bytes()
    path = tmp_path / f"{NAME}.pt"
    path.write_bytes(data[: len(data) - 5000])
    _fails(path, motions, "corrupt|truncated")


def test_nan_rows(motions, tmp_path, raw):
    raw[40:43, 162:170] = np.nan
    path = _write(tmp_path, raw)
    _fails(path, motions, r"NaN or inf in 3 frame\(s\) \(40-42\)")
    clip = load_clip(path, objects_dir=motions / "objects", repair_missing=True)
    assert np.isfinite(clip.body_pos).all() and any("repaired: 3 frame" in p for p in clip.problems)


def test_wrong_column_count(motions, tmp_path, raw):
    _fails(_write(tmp_path, raw[:, :590]), motions, r"\(T, 591\).*\(196, 590\)")


def test_non_unit_quaternion(motions, tmp_path, raw):
    raw[17, 383 + 4 * 5 : 383 + 4 * 6] *= 2.0  # R_Hip of frame 17
    _fails(
        _write(tmp_path, raw),
        motions,
        r"non-unit quaternion in body_quat_xyzw \(norm 2\.0+ at frame 17, body R_Hip\)",
    )


def test_too_short(motions, tmp_path, raw):
    _fails(_write(tmp_path, raw[:45]), motions, r"too short: 1\.50 s \(45 frames")


def test_bad_contact_labels(motions, tmp_path, raw):
    raw[5, 340] = 0.5
    _fails(_write(tmp_path, raw), motions, "labels")


def test_missing_mesh_gives_a_box_from_the_clip(motions, tmp_path, raw):
    path = _write(tmp_path, raw)
    clip = load_clip(path)  # default objects dir next to the clip: tmp_path/../objects does not exist
    assert clip.object.origin.startswith("box ") and any("object 'largebox': box" in p for p in clip.problems)


def test_cli_prints_one_line_and_exits_2(motions, tmp_path, raw, capsys):
    path = _write(tmp_path, raw[:, :590])
    assert main(["data", "inspect", path, "--objects", str(motions / "objects")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("robot-hoi data: error:") and path in err
    assert "Traceback" not in err

"""The reader on the real reference clips in ../shared (skipped without it)."""

import json

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from robot_hoi.cli import main
from robot_hoi.data.clip import load_clip
from robot_hoi.data.intermimic import read_intermimic_matrix
from robot_hoi.data.kinematics import bone_offsets
from robot_hoi.data.layout import BODY_INDEX, BODY_PARENTS, FINGERS, R_THUMB, SUBJECT_HEIGHTS_M, mirror_body
from robot_hoi.data.objects import to_world
from robot_hoi.data.summary import clip_summary
from robot_hoi.data.validate import validate_clip

pytestmark = pytest.mark.shared


def _all_clips(motions):
    return sorted((motions / "clips").glob("*.pt")) + sorted((motions / "physics_corrected").glob("*.pt"))


@pytest.mark.slow
def test_every_reference_clip_loads_validates_and_inspects(motions, capsys):
    paths = _all_clips(motions)
    assert len(paths) == 8
    for path in paths:
        clip = load_clip(path)
        validate_clip(clip, path=path)
        capsys.readouterr()
        assert main(["data", "inspect", str(path), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        assert report["frames"] == clip.num_frames and report["object"]["loaded"]
        assert clip.subject_height_m == SUBJECT_HEIGHTS_M[clip.subject] and clip.height_source == "table"
        assert clip.license.startswith("CC BY-NC-SA 4.0")
        # stored and inferred frame-level contact agree on the reference clips
        assert report["contact"]["agreement"] > 0.95, path.name


def test_reader_matches_torch_load(motions):
    path = motions / "clips" / "sub3_largebox_003.pt"
    expected = torch.load(path, weights_only=True).detach().numpy()
    np.testing.assert_array_equal(read_intermimic_matrix(path), expected)


def test_sources_md_facts_hold(motions):
    clip = load_clip(motions / "clips" / "sub2_largetable_003.pt")
    np.testing.assert_allclose(clip.body_pos[:, 0], clip.root_pos, atol=1e-6)
    parent, child = BODY_PARENTS[BODY_INDEX["L_Knee"]], BODY_INDEX["L_Knee"]
    for frame in (0, 50, 150):
        rel = Rotation.from_quat(clip.body_quat_xyzw[frame, parent]).inv() * Rotation.from_quat(
            clip.body_quat_xyzw[frame, child]
        )
        np.testing.assert_allclose((rel.inv() * Rotation.from_rotvec(clip.dof_rotvec[frame, child - 1])).magnitude(),
                                   0.0, atol=1e-5)  # fmt: skip
    points = to_world(clip.object.sample_points, clip.object_pos[:1], clip.object_quat_xyzw[:1])[0]
    assert abs(points[:, 2].min()) < 0.01  # the object rests on the floor in frame 0
    assert bone_offsets(clip.body_pos, clip.body_quat_xyzw).std(axis=0).max() < 1e-5  # constant skeleton
    assert clip.num_frames == 198 and clip.fps == 30.0


def test_physics_corrected_clip_drops_its_placeholder_frame(motions):
    path = motions / "physics_corrected" / "sub2_largetable_003.pt"
    raw = read_intermimic_matrix(path)
    assert not raw[0, :330].any()
    clip = load_clip(path)
    assert clip.num_frames == raw.shape[0] - 1
    np.testing.assert_allclose(clip.root_pos[0], raw[1, 0:3], atol=1e-6)
    assert any("placeholder" in p for p in clip.problems)


def test_sub8_finger_rows_are_repaired(motions):
    path = motions / "clips" / "sub8_largebox_000.pt"
    raw = read_intermimic_matrix(path).astype(np.float64)
    raw_offsets = bone_offsets(raw[:, 162:318].reshape(-1, 52, 3), raw[:, 383:591].reshape(-1, 52, 4))
    assert raw_offsets[:, list(FINGERS)].std(axis=0).max() > 0.05  # the bug is there
    clip = load_clip(path)
    offsets = bone_offsets(clip.body_pos, clip.body_quat_xyzw)
    assert offsets[:, list(FINGERS)].std(axis=0).max() < 1e-5
    median = np.median(offsets, axis=0)
    for j in FINGERS:  # left and right hands mirror each other within a few mm
        if j not in R_THUMB:
            np.testing.assert_allclose(median[j], median[mirror_body(j)] * (1, -1, 1), atol=0.006)
    # body joints untouched
    np.testing.assert_array_equal(clip.body_pos[:, :18], raw[:, 162:216].reshape(-1, 18, 3))
    assert any("finger rows" in p for p in clip.problems)


def test_sub2_needs_no_finger_fix(motions):
    clip = load_clip(motions / "clips" / "sub2_largetable_000.pt")
    assert not any("finger" in p for p in clip.problems)
    assert any("sign flips" in p for p in clip.problems)
    assert (np.sum(clip.body_quat_xyzw[1:] * clip.body_quat_xyzw[:-1], axis=-1) > 0).all()


def test_contact_inference_flags_the_lift_of_sub3(motions):
    clip = load_clip(motions / "clips" / "sub3_largebox_003.pt")
    t = clip.times
    lifted = (t >= 1.2) & (t <= 5.0)
    assert clip.inferred_contact[lifted].all()
    assert not clip.inferred_contact[t < 0.25].any()  # walking up to the box
    hands = [BODY_INDEX["L_Wrist"], BODY_INDEX["R_Wrist"]]
    assert (clip.inferred_body_contact[np.ix_(lifted, hands)] == 1).all()
    assert (clip.inferred_body_contact[lifted, BODY_INDEX["Head"]] == -1).all()
    report = clip_summary(clip)
    segments = report["lift"]["lifted_segments"]
    assert len(segments) == 1 and segments[0]["start_s"] == pytest.approx(1.2, abs=0.2)
    assert segments[0]["end_s"] == pytest.approx(5.0, abs=0.2)


def test_missing_objects_dir_gives_a_box_unless_optional(motions, tmp_path):
    path = motions / "clips" / "sub3_largebox_003.pt"
    clip = load_clip(path, objects_dir=tmp_path)
    assert "estimated from the clip" in clip.object.origin
    assert np.all((clip.object.extents > 0.2) & (clip.object.extents < 0.7))  # the real box: 0.47 x 0.46 x 0.41
    clip = load_clip(path, objects_dir=tmp_path, object_optional=True)
    assert clip.object is None and not clip.inferred_contact.any()
    assert any("object not loaded" in p for p in clip.problems)


def test_object_name_for_a_renamed_file(motions, tmp_path, capsys):
    path = tmp_path / "take1.pt"
    path.write_bytes((motions / "clips" / "sub3_largebox_003.pt").read_bytes())
    assert main(["data", "inspect", str(path)]) == 2
    assert "--object-name" in capsys.readouterr().err
    argv = [
        "data",
        "inspect",
        str(path),
        "--object-name",
        "largebox",
        "--objects",
        str(motions / "objects"),
        "--json",
    ]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["object"]["name"] == "largebox" and report["height_source"] == "estimated"
    assert report["subject_height_m"] == pytest.approx(1.941, abs=0.04)  # skeleton estimate vs the table

"""`robot-hoi retarget`: JSON report shape, files written, one-line user errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robot_hoi.cli import main
from robot_hoi.retarget.motion import RobotMotion


@pytest.mark.slow
def test_default_clip_json_report_motion_and_video(tmp_path, capsys):
    out = tmp_path / "motion.npz"
    video = tmp_path / "motion.mp4"
    rc = main(["retarget", "-o", str(out), "--json", "--video", str(video), "--video-backend", "matplotlib",
               "--video-stride", "100"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert report["clip"].startswith("synth_lift_place")
    assert report["frames"] > 100 and report["fps"] == 30.0 and 0.6 < report["scale"] < 0.9
    assert set(report["position_error"]) == {"pelvis", "legs", "feet", "torso", "head", "arms", "wrists", "fingers"}
    for entry in report["position_error"].values():
        assert set(entry) == {"mean_cm", "max_cm"} and 0.0 <= entry["mean_cm"] <= entry["max_cm"]
    assert set(report["feet"]) == {"max_penetration_cm", "frames_penetrating_over_5mm"}
    assert report["feet"]["max_penetration_cm"] == 0.0
    assert set(report["joint_limits"]) == {"frame_joint_hits", "joints"}
    for side in ("left", "right"):
        hand = report["anchor"][side]
        assert 0.0 < hand["frames_anchored_frac"] <= 1.0
        assert hand["robot_surface_dist_cm_mean"] >= 0.0 and hand["human_surface_dist_cm_mean"] >= 0.0
    assert set(report["hands_in_object"]) == {"robot_max_cm", "robot_frames_over_1cm", "human_max_cm",
                                              "human_frames_over_1cm"}
    assert report["video"] == {"path": str(video), "renderer": "matplotlib"}
    assert video.stat().st_size > 1000

    motion = RobotMotion.load(out)
    assert motion.num_frames == report["frames"] and motion.embodiment == "g1_inspire"
    assert motion.meta["report"]["position_error"] == report["position_error"]
    assert np.isfinite(motion.qpos).all()


def test_bad_output_name_is_a_one_line_error(tmp_path, capsys):
    assert main(["retarget", "-o", str(tmp_path / "motion.pkl")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "must end in .npz" in err


def test_missing_clip_is_a_one_line_error(tmp_path, capsys):
    assert main(["retarget", str(tmp_path / "nope.pt"), "-o", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert "nope.pt" in err and "Traceback" not in err


@pytest.mark.parametrize("flag", [["--video-stride", "0", "--video", "x.mp4"], ["--video", "x.avi"]])
def test_bad_video_flags(tmp_path, capsys, flag):
    assert main(["retarget", "-o", str(tmp_path / "m.npz"), *flag]) == 2


@pytest.mark.slow
def test_a_folder_of_clips_prints_one_feasibility_table(tmp_path, capsys):
    """One row per clip with its physics-gate verdict; a clip that does not load is a row saying why."""
    from robot_hoi.data.synth import embedded_clip

    folder = tmp_path / "clips"
    embedded_clip("lift_place").save(folder / "lift_place.npz")
    (folder / "broken.pt").write_bytes(b"not a clip")
    assert main(["retarget", str(folder), "-o", str(tmp_path / "motions")]) == 0
    lines = capsys.readouterr().out.splitlines()
    table = lines[lines.index(next(line for line in lines if line.startswith("clip "))):]
    assert table[0].split()[:3] == ["clip", "frames", "held"]
    rows = {line.split()[0]: line for line in table[1:-1]}
    assert set(rows) == {"broken.pt", "synth_lift_place_seed0"}
    assert "ERROR" in rows["broken.pt"] and rows["synth_lift_place_seed0"].split()[3] in ("PASS", "FAIL")
    assert table[-1].endswith("clips pass the physics gate")
    assert (tmp_path / "motions" / "synth_lift_place_seed0.npz").is_file()


def test_a_folder_with_a_video_or_a_file_output_is_refused(tmp_path, capsys):
    assert main(["retarget", str(tmp_path), "-o", str(tmp_path / "m.npz")]) == 2
    assert "names a folder" in capsys.readouterr().err


def test_each_retarget_setting_has_one_spelling(capsys):
    """The retarget settings are the task config's retarget: block, --set retarget.KEY=VALUE as for training (the
    help names every key), not flags of their own as well."""
    from dataclasses import fields

    from robot_hoi.tasks.interaction.env_cfg import RetargetCfg

    with pytest.raises(SystemExit):
        main(["retarget", "--help"])
    text = capsys.readouterr().out
    assert "--set retarget.KEY=VALUE" in text
    for key in (f.name for f in fields(RetargetCfg)):
        assert key in " ".join(text.split())
    for old in ("--leg-loads", "--dynamics", "--finger-closure", "--squeeze-toward", "--squeeze-depth",
                "--fingertip-underside-reach", "--anchor-mode", "--object-collision"):
        assert old not in text

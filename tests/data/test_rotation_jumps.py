"""One-frame root and object rotation glitches: validation fails on them, --repair interpolates them."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from robot_hoi.cli import main
from robot_hoi.data.clip import load_clip
from robot_hoi.data.validate import ROT_JUMP_DEG_S, clip_warnings, rotation_glitches, rotation_steps_deg
from robot_hoi.errors import DataError

FRAME = 40


def _turn(quat_xyzw: np.ndarray, degrees: float) -> np.ndarray:
    return (Rotation.from_euler("z", degrees, degrees=True) * Rotation.from_quat(quat_xyzw)).as_quat()


def _rotate_frame(clip, frame: int, degrees: float) -> None:
    """The whole body of one frame turned about the pelvis (what a root glitch in MoCap looks like)."""
    turn = Rotation.from_euler("z", degrees, degrees=True)
    pelvis = clip.root_pos[frame].copy()
    clip.body_pos[frame] = turn.apply(clip.body_pos[frame] - pelvis) + pelvis
    clip.body_quat_xyzw[frame] = (turn * Rotation.from_quat(clip.body_quat_xyzw[frame])).as_quat()
    clip.root_quat_xyzw[frame] = clip.body_quat_xyzw[frame, 0]


def test_detects_spikes_not_steps_or_turns():
    quat = Rotation.from_euler("z", np.linspace(0, 90, 60)[:, None], degrees=True).as_quat()  # 45 deg/s: a turn
    assert not rotation_glitches(quat, 30.0).any()
    spiked = quat.copy()
    spiked[FRAME] = _turn(quat[FRAME], 11.7)
    assert np.flatnonzero(rotation_glitches(spiked, 30.0)).tolist() == [FRAME]
    stepped = quat.copy()
    stepped[FRAME:] = _turn(quat[FRAME:], 11.7)  # stays turned: not a one-frame glitch, nothing safe to repair
    assert not rotation_glitches(stepped, 30.0).any()
    assert rotation_steps_deg(stepped).max() * 30.0 > ROT_JUMP_DEG_S


def test_root_glitch_fails_validation_and_repair_fixes_it(tmp_path, lift_clip):
    clip = lift_clip.copy()
    _rotate_frame(clip, FRAME, 11.7)
    path = clip.save(tmp_path / "glitch.npz")
    with pytest.raises(DataError, match=rf"root rotation jumps 11\.7 deg.*frame\(s\) {FRAME}.*--repair"):
        load_clip(path)
    fixed = load_clip(path, repair_missing=True)
    assert any("repaired: 1 frame(s) where the root rotation jumps" in p for p in fixed.problems)
    assert rotation_steps_deg(fixed.root_quat_xyzw).max() < 5.0
    assert np.abs(fixed.body_pos[FRAME] - lift_clip.body_pos[FRAME]).max() < 0.02


def test_object_glitch_repair_keeps_the_body(tmp_path, lift_clip):
    clip = lift_clip.copy()
    clip.object_quat_xyzw[FRAME] = _turn(clip.object_quat_xyzw[FRAME], 20.0)
    path = clip.save(tmp_path / "glitch.npz")
    with pytest.raises(DataError, match="object rotation jumps 20.0 deg"):
        load_clip(path)
    fixed = load_clip(path, repair_missing=True)
    assert np.array_equal(fixed.body_pos, lift_clip.body_pos)
    assert rotation_steps_deg(fixed.object_quat_xyzw).max() < 5.0


def test_lasting_jump_is_a_warning(lift_clip):
    clip = lift_clip.copy()
    clip.object_quat_xyzw[FRAME:] = _turn(clip.object_quat_xyzw[FRAME:], 15.0)
    assert any(w.startswith("object turns faster than") for w in clip_warnings(clip))


def test_cli_error_names_a_flag_every_command_has(tmp_path, lift_clip, capsys):
    clip = lift_clip.copy()
    _rotate_frame(clip, FRAME, 11.7)
    path = str(clip.save(tmp_path / "glitch.npz"))
    assert main(["data", "inspect", path]) == 2
    assert "--repair" in capsys.readouterr().err
    assert main(["data", "inspect", path, "--repair"]) == 0
    for command in (["train"], ["eval", "x.pt"], ["retarget", "-o", "x.npz"], ["sim2sim", "--policy", "p.onnx"],
                    ["export", "onnx"], ["play", "x.pt", "--video", "x.mp4"]):
        with pytest.raises(SystemExit) as exit_info:
            main([*command, "--repair", "--objects", str(tmp_path), "--help"])
        assert exit_info.value.code == 0, command


def test_checkpoint_given_to_inspect_says_so(tmp_path, capsys):
    path = tmp_path / "model_10.pt"
    torch.save({"model": {"w": torch.zeros(2)}, "iteration": 10}, path)
    assert main(["data", "inspect", str(path)]) == 2
    err = capsys.readouterr().err
    assert "checkpoint" in err and "opcode" not in err and "robot-hoi eval" in err

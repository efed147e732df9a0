"""`robot-hoi play`: a policy in the training simulation, rendered with the reference ghost, as a user runs it."""

from __future__ import annotations

import subprocess
import sys

import pytest

from robot_hoi.cli import main


@pytest.mark.slow
def test_play_writes_a_video_of_an_exported_policy(tmp_path, capsys):
    onnx = tmp_path / "untrained.onnx"
    assert main(["export", "onnx", "--untrained", "-o", str(onnx), "--recorded", "20"]) == 0
    capsys.readouterr()
    video = tmp_path / "play.mp4"
    done = subprocess.run([sys.executable, "-m", "robot_hoi.cli", "play", str(onnx), "--video", str(video),
                           "--seconds", "0.3"], capture_output=True, text=True, timeout=600)
    if "no offscreen OpenGL backend" in done.stderr:
        pytest.skip("no offscreen OpenGL backend (egl, osmesa) here")
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"wrote {video}" in done.stdout and "ghost = the reference" in done.stdout
    import imageio.v3 as iio

    frames = iio.imread(video)
    assert frames.shape[0] >= 5 and frames.shape[1:] == (480, 640, 3) and frames.std() > 5


def test_play_refuses_other_suffixes(capsys):
    assert main(["play", "x.pt", "--video", "x.gif"]) == 2
    assert "must end in .mp4" in capsys.readouterr().err

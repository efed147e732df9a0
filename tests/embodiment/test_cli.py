"""`robot-hoi model ...` end to end through robot_hoi.cli.main."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import mujoco
import pytest

from robot_hoi.cli import main
from robot_hoi.embodiment.urdf import COMMITTED_URDF


def test_show_json_shape(capsys):
    assert main(["model", "show", "--embodiment", "g1_inspire", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["embodiment"] == "g1_inspire" and out["num_actuators"] == 41
    joints = out["joints"]
    assert len(joints) == 53
    assert [j["kind"] for j in joints].count("body") == 29
    assert [j["kind"] for j in joints].count("hand") == 12
    assert [j["kind"] for j in joints].count("passive") == 12
    first = joints[0]
    assert first["name"] == "left_hip_pitch_joint"
    assert set(first) >= {"name", "kind", "range", "effort", "kp", "kd", "default"}
    assert first["range"] == [-2.5307, 2.8798] and first["effort"] == 88 and first["kp"] == 100
    passive = joints[-1]
    assert passive["kp"] is None and passive["mimic"]["joint"] == "R_pinky_proximal_joint"


def test_show_table(capsys):
    assert main(["model", "show"]) == 0
    out = capsys.readouterr().out
    assert "L_thumb_proximal_yaw_joint" in out and "41 actuators" in out


def test_mjcf_writes_a_file_plain_mujoco_loads(tmp_path, capsys):
    path = tmp_path / "out" / "g1.xml"
    assert main(["model", "mjcf", "--embodiment", "g1_inspire", "-o", str(path), "--self-collision", "on"]) == 0
    model = mujoco.MjModel.from_xml_path(str(path))
    assert model.nu == 41 and model.nexclude > 0
    assert not list(tmp_path.glob("out/.g1.xml*")), "no temporary file left behind"


def test_urdf_command_matches_committed_file(tmp_path):
    path = tmp_path / "g1.urdf"
    assert main(["model", "urdf", "-o", str(path)]) == 0
    assert path.read_text() == COMMITTED_URDF.read_text()


def test_user_errors_are_one_line_exit_2(tmp_path, capsys):
    assert main(["model", "show", "--embodiment", "nope"]) == 2
    err = capsys.readouterr().err
    assert "unknown embodiment 'nope'" in err and "Traceback" not in err
    assert main(["model", "show", "--set", "decimation=zero"]) == 2
    assert "expected an integer" in capsys.readouterr().err


def test_view_without_display_explains_offscreen_rendering(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    assert main(["model", "view"]) == 2
    err = capsys.readouterr().err
    assert "MUJOCO_GL=egl" in err and "robot-hoi model render" in err


@pytest.mark.slow
def test_render_png_or_clear_gl_error(tmp_path):
    """Headless render in a fresh interpreter (MUJOCO_GL is read when mujoco is first imported): a real picture
    where an OpenGL backend works, otherwise a clear one-line error naming MUJOCO_GL."""
    path = tmp_path / "robot.png"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL")}
    result = subprocess.run(
        [sys.executable, "-m", "robot_hoi.cli", "model", "render", "-o", str(path), "--width", "96", "--height",
         "128", "--no-meshes"], env=env, capture_output=True, text=True, timeout=300)
    if result.returncode == 0:
        import imageio.v3 as iio

        image = iio.imread(path)
        assert image.shape == (128, 96, 3) and image.std() > 5  # not a blank frame
    else:
        assert result.returncode == 2, result.stderr
        assert "MUJOCO_GL" in result.stderr and "Traceback" not in result.stderr

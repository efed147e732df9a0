import json

import numpy as np
import pytest

from robot_hoi.cli import main
from robot_hoi.commands import data as data_cli
from robot_hoi.data import synth
from robot_hoi.data.clip import load_clip

REPORT_KEYS = {"file", "name", "fps", "frames", "duration_s", "subject", "subject_height_m", "height_source",
               "object", "contact", "lift", "problems", "source", "license"}  # fmt: skip


def test_cli_lists_match_the_generator():
    assert data_cli.KINDS == synth.KINDS and data_cli.ARTIFACTS == synth.ARTIFACTS


def test_synth_then_inspect_json(tmp_path, capsys):
    out = tmp_path / "box.npz"
    assert main(["data", "synth", "-o", str(out), "--kind", "push", "--seed", "2"]) == 0
    assert out.is_file() and (tmp_path / "box.json").is_file()
    capsys.readouterr()
    assert main(["data", "inspect", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert set(report) == REPORT_KEYS
    assert report["frames"] == load_clip(out).num_frames and report["fps"] == 30.0
    assert set(report["contact"]) == {"stored_frames", "inferred_frames", "agreement", "stored_segments",
                                      "inferred_segments"}  # fmt: skip
    segment = report["contact"]["stored_segments"][0]
    assert set(segment) == {"start_frame", "end_frame", "start_s", "end_s"}
    assert report["lift"]["lifted"] is False and report["problems"] == []


def test_synth_with_artifacts_and_text_inspect(tmp_path, capsys):
    out = tmp_path / "noisy.npz"
    assert main(["data", "synth", "-o", str(out), "--artifacts", "noise,floating_contact"]) == 0
    capsys.readouterr()
    assert main(["data", "inspect", str(out)]) == 0
    text = capsys.readouterr().out
    assert "synthetic artifacts: noise, floating_contact" in text and "contact   stored:" in text


def test_bad_file_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "broken.pt"
    bad.write_bytes(b"not a zip at all")
    assert main(["data", "inspect", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(bad) in err and "not a torch zip archive" in err


def test_missing_frames_need_repair(tmp_path, capsys):
    out = tmp_path / "holes.npz"
    assert main(["data", "synth", "-o", str(out), "--artifacts", "missing_frames"]) == 0
    assert main(["data", "inspect", str(out)]) == 2
    assert "NaN or inf" in capsys.readouterr().err
    assert main(["data", "inspect", str(out), "--repair"]) == 0


def test_convert_resamples_and_scales(tmp_path):
    src = tmp_path / "src.npz"
    assert main(["data", "synth", "-o", str(src)]) == 0
    dst = tmp_path / "robot50.npz"
    assert main(["data", "convert", str(src), "-o", str(dst), "--fps", "50", "--to-robot", "g1_inspire"]) == 0
    clip = load_clip(dst)
    assert clip.fps == 50.0 and clip.subject_height_m == pytest.approx(1.32)
    assert clip.body_pos[..., 2].max() < 1.75 * 1.32 / 1.75 + 0.01


def test_view_writes_a_png(tmp_path):
    pytest.importorskip("mujoco")
    out = tmp_path / "view.png"
    assert (
        main(
            [
                "data",
                "view",
                "embedded:push",
                "--embodiment",
                "g1_inspire",
                "-o",
                str(out),
                "--keyframes",
                "3",
            ]
        )
        == 0
    )
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    import matplotlib.image as mpimg

    image = mpimg.imread(out)
    assert image.shape[1] > image.shape[0] > 200 and np.ptp(image[..., :3]) > 0.5  # drawn, not blank


def test_view_rejects_unknown_output(tmp_path, capsys):
    assert main(["data", "view", "embedded:push", "--embodiment", "", "-o", str(tmp_path / "x.gif")]) == 2
    assert "png" in capsys.readouterr().err

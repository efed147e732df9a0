"""Offscreen videos: rendered when a GL backend works, a clear message (and no crash) when none does."""

from __future__ import annotations

import numpy as np
import pytest

from sim2sim.video import VideoRequest, render_videos


def _request(target, frames: int = 4) -> VideoRequest:
    from sim2sim.scene import load_model

    model = load_model(target.scene)
    qpos = np.repeat(model.qpos0[None], frames, axis=0)
    return VideoRequest("clip.mp4", "test", target.scene, qpos, 30.0)


def test_no_gl_backend_degrades_to_a_message(target, tmp_path, monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "no-such-backend")
    out = render_videos([_request(target)], tmp_path / "videos", timeout_s=120)
    assert out["backend"] is None and out["files"] == []
    assert "no OpenGL backend worked" in out["message"] and "MUJOCO_GL=egl" in out["message"]
    assert not (tmp_path / "videos" / "clip.mp4").exists()


def test_egl_renders_an_mp4(target, tmp_path, monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "egl")
    out = render_videos([_request(target, frames=8)], tmp_path / "videos", timeout_s=120)
    if out["backend"] is None:
        pytest.skip(f"no EGL on this machine: {out['message']}")
    import imageio.v3 as iio

    frames = iio.imread(out["files"][0])
    assert frames.shape[1:] == (480, 640, 3) and frames.std() > 5

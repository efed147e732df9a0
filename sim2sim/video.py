"""MP4s of chosen episodes, rendered offscreen with mujoco.Renderer from the recorded robot and object states.

Rendering needs an OpenGL backend that works without a display, chosen by MUJOCO_GL before mujoco is imported:
    egl     libEGL with a GPU driver (NVIDIA) or Mesa's EGL (software llvmpipe works too): apt install libegl1
    osmesa  pure software rendering: apt install libosmesa6
    glfw    needs an X display (or Xvfb)
A backend is tried in a fresh process each (the choice is fixed once mujoco is imported): MUJOCO_GL when set,
else egl, then osmesa. When none works the report says so and keeps its plots; nothing else fails.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from dataclasses import dataclass
from pathlib import Path
from queue import Empty

import numpy as np

from deploy.safety import Phase

FALLBACK_BACKENDS = ("egl", "osmesa")
WIDTH, HEIGHT = 640, 480
VIDEO_FPS = 15.0  # every other control tick: software GL (Mesa llvmpipe) takes ~40 ms a frame
HOW_TO = ("videos need an offscreen OpenGL backend: MUJOCO_GL=egl (libEGL with a GPU driver or Mesa) or "
          "MUJOCO_GL=osmesa (apt install libosmesa6)")


@dataclass
class VideoRequest:
    file: str  # file name inside the videos folder, e.g. "A_nominal_ep0.mp4"
    title: str
    scene: bytes  # MJB of the episode's model
    qpos: np.ndarray  # (N, nq) states, one per control tick
    fps: float
    ghost_qpos: np.ndarray | None = None  # (N, nq) the reference at the same ticks, drawn as a translucent ghost


def reference_qpos(trace: dict, motion, layout, warmup_frames: int) -> np.ndarray:
    """(N, nq) per recorded tick: the recorded state with robot and object moved to the reference frame the
    policy tracks then (frame 0 until the policy has run its warmup, as the runtime's clock holds it)."""
    qpos = np.array(trace["qpos"], dtype=np.float64)
    times = np.asarray(trace["time_s"], dtype=np.float64)
    running = np.flatnonzero(np.asarray(trace["phase"]) == int(Phase.POLICY))
    start = times[running[0]] if len(running) else np.inf
    ticks = np.where(times >= start, np.round((times - start) * motion.fps), 0)
    frames = np.clip(ticks.astype(int) - warmup_frames, 0, motion.num_frames - 1)
    qpos[:, 0:3] = motion.root_pos[frames]
    qpos[:, 3:7] = motion.root_quat_wxyz[frames]
    qpos[:, layout.body_qpos] = motion.joint_pos[frames][:, :len(layout.body_qpos)]
    qpos[:, layout.hand_qpos] = motion.joint_pos[frames][:, len(layout.body_qpos):][:, :len(layout.hand_qpos)]
    qpos[:, layout.object_qpos:layout.object_qpos + 3] = motion.object_pos[frames]
    qpos[:, layout.object_qpos + 3:layout.object_qpos + 7] = motion.object_quat_wxyz[frames]
    return qpos


def _render(backend: str, requests: list[VideoRequest], out_dir: str, queue) -> None:
    os.environ["MUJOCO_GL"] = backend
    try:
        from robot_hoi.sim.video import StateRenderer, write_mp4
        from sim2sim.scene import load_model

        written = []
        for req in requests:
            model = load_model(req.scene)
            model.vis.quality.shadowsize = 0  # shadows and reflections cost 2-5x on a software renderer
            model.mat_reflectance[:] = 0.0
            stride = max(1, int(round(req.fps / VIDEO_FPS)))
            ghosts = req.ghost_qpos[::stride] if req.ghost_qpos is not None else [None] * len(req.qpos[::stride])
            with StateRenderer(model, (WIDTH, HEIGHT), distance=3.2) as renderer:
                frames = [renderer.render(q, ghost_qpos=g) for q, g in zip(req.qpos[::stride], ghosts, strict=True)]
            written.append(str(write_mp4(Path(out_dir) / req.file, frames, req.fps / stride)))
        queue.put(("ok", written))
    except Exception as exc:  # reported to the parent, which tries the next backend
        queue.put(("error", f"{type(exc).__name__}: {exc}"))


def _wait(queue, process, timeout_s: float) -> tuple[str, object]:
    """The renderer's answer, or an error when it dies (a GL library can crash the process) or times out."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            return queue.get(timeout=0.5)
        except Empty:
            if not process.is_alive():
                try:
                    return queue.get(timeout=0.5)
                except Empty:
                    return "error", f"renderer process died (exit code {process.exitcode})"
    return "error", f"no answer within {timeout_s:.0f} s"


def render_videos(requests: list[VideoRequest], out_dir: str | os.PathLike, timeout_s: float = 300.0) -> dict:
    """Render every request; returns {"backend", "files", "message"} (backend None: no video, see message)."""
    if not requests:
        return {"backend": None, "files": [], "message": "no episodes chosen for video"}
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    requested = os.environ.get("MUJOCO_GL")
    backends = (requested,) if requested else FALLBACK_BACKENDS
    ctx = multiprocessing.get_context("spawn")
    problems = []
    for backend in backends:
        queue = ctx.Queue()
        process = ctx.Process(target=_render, args=(backend, requests, str(out_dir), queue), daemon=True)
        process.start()
        status, payload = _wait(queue, process, timeout_s)
        process.join(timeout=10)
        if process.is_alive():
            process.kill()
        if status == "ok":
            return {"backend": backend, "files": payload, "message": f"rendered with MUJOCO_GL={backend}"}
        problems.append(f"{backend}: {payload}")
    return {"backend": None, "files": [],
            "message": "no video: no OpenGL backend worked (" + "; ".join(problems) + "). " + HOW_TO}

"""Offscreen MP4s of MuJoCo states with the reference drawn as a translucent ghost: the one renderer behind
`robot-hoi play`, the retarget video and the sim2sim videos.

The ghost is the same model in the reference's state (a second MjData), its moving geoms added to the scene with
`mjv_addGeoms` and tinted GHOST_RGBA, so the robot and its reference can be compared by eye; where the reference
is a set of points (the retarget's human targets) `add_ghost_skeleton` draws it in the same tint.

MUJOCO_GL must name a working offscreen backend (egl, osmesa) before mujoco is imported:
robot_hoi.retarget.video.choose_gl_backend picks one.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import imageio.v2 as imageio
import mujoco
import numpy as np

from deploy.atomic import atomic_path

GHOST_RGBA = (0.25, 0.8, 1.0, 0.3)  # light blue, mostly transparent
SIZE = (640, 480)


def add_ghost(scene: mujoco.MjvScene, model: mujoco.MjModel, ghost: mujoco.MjData, rgba=GHOST_RGBA) -> None:
    """Append the moving geoms of `ghost` (no floor) to `scene`, drawn translucent in one colour."""
    first = scene.ngeom
    mujoco.mjv_addGeoms(model, ghost, mujoco.MjvOption(), mujoco.MjvPerturb(), mujoco.mjtCatBit.mjCAT_DYNAMIC,
                        scene)
    for geom in scene.geoms[first:scene.ngeom]:
        geom.rgba[:] = rgba
        geom.matid = -1  # a material's own colour would win over rgba
        geom.segid = -1


def add_ghost_skeleton(scene: mujoco.MjvScene, points: np.ndarray, bones: Iterable[tuple[int, int]],
                       rgba=GHOST_RGBA, radius: float = 0.02) -> None:
    """Points (N, 3) as spheres and bones (i, j) as capsules between them, in the ghost's tint."""
    rgba = np.asarray(rgba, dtype=np.float32)
    for p in points:
        if scene.ngeom >= scene.maxgeom:
            return
        mujoco.mjv_initGeom(scene.geoms[scene.ngeom], mujoco.mjtGeom.mjGEOM_SPHERE, np.array([radius, 0, 0]),
                            np.asarray(p, dtype=np.float64), np.eye(3).ravel(), rgba)
        scene.ngeom += 1
    for i, j in bones:
        if scene.ngeom >= scene.maxgeom:
            return
        geom = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), np.eye(3).ravel(), rgba)
        mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, radius * 0.7,
                             np.asarray(points[i], dtype=np.float64), np.asarray(points[j], dtype=np.float64))
        scene.ngeom += 1


class StateRenderer:
    """Frames of `model` in given states, followed by a free camera, optionally with the reference ghost."""

    def __init__(self, model: mujoco.MjModel, size=SIZE, distance: float = 3.0, azimuth: float = 135.0,
                 elevation: float = -18.0, fancy: bool = False):
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, size[0])
        model.vis.global_.offheight = max(model.vis.global_.offheight, size[1])
        self.model = model
        self.data = mujoco.MjData(model)
        self.ghost = mujoco.MjData(model)
        self.fancy = fancy  # shadows and reflections: 2-5x slower with software GL
        self.renderer = mujoco.Renderer(model, height=size[1], width=size[0])
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.distance, self.camera.azimuth, self.camera.elevation = distance, azimuth, elevation

    def __enter__(self) -> StateRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.renderer.close()

    @staticmethod
    def _pose(model, data, qpos, mocap_pos=None, mocap_quat=None) -> None:
        data.qpos[:] = qpos
        if mocap_pos is not None:
            data.mocap_pos[:] = np.reshape(mocap_pos, data.mocap_pos.shape)
            data.mocap_quat[:] = np.reshape(mocap_quat, data.mocap_quat.shape)
        mujoco.mj_kinematics(model, data)

    def render(self, qpos, *, mocap_pos=None, mocap_quat=None, ghost_qpos=None,
               decorate: Callable[[mujoco.MjvScene], None] | None = None) -> np.ndarray:
        """One RGB frame (H, W, 3) of the state `qpos`, the ghost at `ghost_qpos`, then `decorate(scene)`."""
        self._pose(self.model, self.data, qpos, mocap_pos, mocap_quat)
        self.camera.lookat[:] = (self.data.qpos[0], self.data.qpos[1], 0.6)
        self.renderer.update_scene(self.data, camera=self.camera)
        scene = self.renderer.scene
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self.fancy
        scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = self.fancy
        if ghost_qpos is not None:
            self._pose(self.model, self.ghost, ghost_qpos, mocap_pos, mocap_quat)
            add_ghost(scene, self.model, self.ghost)
        if decorate is not None:
            decorate(scene)
        return self.renderer.render().copy()


def write_mp4(path: str | Path, frames: Iterable[np.ndarray], fps: float) -> Path:
    """H.264 MP4, written atomically (frames may be a generator)."""
    path = Path(path)
    with atomic_path(path) as tmp, imageio.get_writer(tmp, fps=fps, codec="libx264", macro_block_size=8,
                                                      format="FFMPEG") as writer:
        for frame in frames:
            writer.append_data(frame)
    return path

"""Look at the robot: interactive MuJoCo viewer when a display exists, offscreen PNG otherwise.

MUJOCO_GL picks the OpenGL backend when mujoco first creates a context: `egl` (GPU or Mesa, headless), `osmesa`
(pure software, apt install libosmesa6) or `glfw` (needs a display). Without a display and without MUJOCO_GL we
choose egl before mujoco is imported.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from deploy.atomic import atomic_path
from robot_hoi.embodiment.collision import COLLISION_GROUP, VISUAL_MESH_GROUP
from robot_hoi.errors import UserError

NO_DISPLAY_HINT = (
    "no display found (DISPLAY/WAYLAND_DISPLAY unset), so the interactive viewer cannot open. "
    "Render a picture offscreen instead: MUJOCO_GL=egl robot-hoi model render -o robot.png "
    "(or MUJOCO_GL=osmesa for pure-software rendering)"
)


def has_display() -> bool:
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def choose_gl_backend() -> str:
    """Set MUJOCO_GL for headless use unless the user chose one; returns the backend in effect.

    Only works before mujoco's first import in this process (mujoco reads MUJOCO_GL then)."""
    if "MUJOCO_GL" not in os.environ and not has_display() and "mujoco" not in sys.modules:
        os.environ["MUJOCO_GL"] = "egl"
    return os.environ.get("MUJOCO_GL", "glfw (default)")


def _show_meshes_not_collision(model) -> None:
    """With Unitree meshes loaded, move the collision primitives to group 3 (hidden; key 3 shows them)."""
    if (model.geom_group == VISUAL_MESH_GROUP).any():
        robot = (model.geom_group == COLLISION_GROUP) & (model.geom_bodyid > 0)
        model.geom_group[robot] = np.int32(3)


def prepared_model(cfg, *, meshes: bool, fixed_base: bool, self_collision: bool | None = None):
    """Model + data at the default keyframe, for looking at."""
    # mujoco only here and below, after choose_gl_backend: it reads MUJOCO_GL when first imported
    import mujoco

    from robot_hoi.embodiment.mjcf import DEFAULT_KEYFRAME, build_model

    model = build_model(cfg, visual_meshes=meshes, fixed_base=fixed_base, self_collision=self_collision)
    _show_meshes_not_collision(model)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(DEFAULT_KEYFRAME).id)
    mujoco.mj_forward(model, data)
    return model, data


def view(cfg, *, meshes: bool, fixed_base: bool, self_collision: bool | None = None) -> None:
    """Blocking interactive viewer (physics runs; the PD holds the default pose)."""
    if not has_display():
        raise UserError(NO_DISPLAY_HINT)
    import mujoco.viewer  # GLFW: only with a display

    model, data = prepared_model(cfg, meshes=meshes, fixed_base=fixed_base, self_collision=self_collision)
    mujoco.viewer.launch(model, data)


def render_png(
    cfg,
    path: str | os.PathLike,
    *,
    width: int = 640,
    height: int = 720,
    meshes: bool,
    azimuth: float = 150.0,
    elevation: float = -15.0,
    distance: float = 2.4,
) -> Path:
    """Render the default pose to a PNG with mujoco.Renderer (offscreen)."""
    backend = choose_gl_backend()
    import mujoco  # after choose_gl_backend

    model, data = prepared_model(cfg, meshes=meshes, fixed_base=False)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # mujoco raises several types for a missing GL
        raise UserError(
            f"offscreen rendering failed with MUJOCO_GL={backend} ({type(exc).__name__}: {exc}); "
            "try MUJOCO_GL=egl (GPU or Mesa EGL) or MUJOCO_GL=osmesa (apt install libosmesa6)"
        ) from None
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = [0.0, 0.0, 0.65]
    camera.azimuth, camera.elevation, camera.distance = azimuth, elevation, distance
    with renderer:
        renderer.update_scene(data, camera=camera)
        pixels = renderer.render()
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        iio.imwrite(tmp, pixels, extension=".png")
    return path

"""An mp4 of a retargeted motion: MuJoCo's offscreen renderer when an OpenGL backend works, else a matplotlib
3D stick figure. The reference (the scaled human's targets) is drawn as a translucent ghost skeleton in the tint
of every reference ghost (robot_hoi.sim.video; red dots in the fallback), the object as its mesh.

MuJoCo picks its GL backend from MUJOCO_GL when it is first imported, so `choose_gl_backend` must run before
anything imports mujoco: it tries EGL, then OSMesa, each in a throw-away subprocess.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
from scipy.spatial.transform import Rotation

from deploy.atomic import atomic_path

GL_BACKENDS = ("egl", "osmesa")
_PROBE = (
    "import mujoco\n"
    "m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size=\"1\"/></worldbody></mujoco>')\n"
    "r = mujoco.Renderer(m, 8, 8); r.update_scene(mujoco.MjData(m)); r.render()\n"
)


def choose_gl_backend() -> str | None:
    """Set MUJOCO_GL to the first backend that renders here; None when none does (or mujoco is loaded already
    without one: then the choice is MuJoCo's own and the renderer is simply tried)."""
    if "mujoco" in sys.modules or os.environ.get("MUJOCO_GL"):
        return os.environ.get("MUJOCO_GL")
    for backend in GL_BACKENDS:
        env = {**os.environ, "MUJOCO_GL": backend}
        if backend == "osmesa":
            env["PYOPENGL_PLATFORM"] = "osmesa"
        try:
            ok = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, timeout=60).returncode == 0
        except subprocess.TimeoutExpired:
            ok = False
        if ok:
            os.environ["MUJOCO_GL"] = backend
            if backend == "osmesa":
                os.environ["PYOPENGL_PLATFORM"] = "osmesa"
            return backend
    return None


def _render_model(cfg, object_asset, meshes: bool):
    """Robot (collision primitives; Unitree's visual meshes too when `meshes` and present), a floor, and the
    object as a mocap mesh body."""
    # mujoco here and below, not at the top: after choose_gl_backend (see the module docstring)
    import mujoco

    from robot_hoi.embodiment import build_robot_spec

    spec = build_robot_spec(cfg, visual_meshes=meshes)
    spec.visual.global_.offwidth = max(spec.visual.global_.offwidth, 1280)
    spec.visual.global_.offheight = max(spec.visual.global_.offheight, 960)
    if object_asset is not None:
        spec.add_mesh(name="hoi_object", uservert=np.asarray(object_asset.vertices).ravel().tolist(),
                      userface=np.asarray(object_asset.faces).ravel().tolist())
        body = spec.worldbody.add_body(name="hoi_object", mocap=True)
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname="hoi_object", contype=0, conaffinity=0,
                      density=0.0, rgba=[0.85, 0.55, 0.25, 1.0])
    return spec.compile()


def target_bones(model, link_names) -> list[tuple[int, int]]:
    """(child, parent) pairs of targets whose links are nearest relatives in the robot's body tree."""
    import mujoco  # after choose_gl_backend

    def body_of(name: str) -> int:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        return body if body >= 0 else int(model.site_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)])

    bodies = [body_of(n) for n in link_names]
    index = {b: i for i, b in enumerate(bodies)}
    bones = []
    for i, body in enumerate(bodies):
        parent = body if index[body] != i else int(model.body_parentid[body])  # a site: the link it sits on
        while parent > 0 and parent not in index:
            parent = int(model.body_parentid[parent])
        if parent in index:
            bones.append((i, index[parent]))
    return bones


def render_mujoco(
    motion, cfg, path: Path, object_asset=None, size=(640, 480), stride: int = 1, pretty: bool = False
) -> None:
    """pretty: Unitree meshes, shadows and reflections (~0.4 s a frame with software GL, vs ~0.04 s)."""
    # sim.video imports mujoco: after choose_gl_backend
    from robot_hoi.sim.video import StateRenderer, add_ghost_skeleton, write_mp4

    model = _render_model(cfg, object_asset, meshes=pretty)
    if model.nq != motion.qpos.shape[1]:
        raise RuntimeError(f"render model has nq {model.nq}, motion has {motion.qpos.shape[1]}")
    bones = target_bones(model, motion.link_names)
    mocap = model.nmocap > 0
    with StateRenderer(model, size, distance=2.4, elevation=-15.0, fancy=pretty) as renderer:
        frames = (renderer.render(motion.qpos[t], mocap_pos=motion.object_pos[t] if mocap else None,
                                  mocap_quat=motion.object_quat_wxyz[t] if mocap else None,
                                  decorate=lambda scene, t=t: add_ghost_skeleton(scene, motion.target_pos[t], bones))
                  for t in range(0, motion.num_frames, stride))
        write_mp4(path, frames, motion.fps / stride)


def render_matplotlib(motion, model, path: Path, object_points_local=None, size=(640, 480), stride: int = 1) -> None:
    """Stick figure: every body joined to its parent, targets as red dots, object samples as orange dots."""
    import matplotlib  # only for this fallback (pyplot ~0.5 s), after choosing the headless Agg backend

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mujoco  # after choose_gl_backend

    data = mujoco.MjData(model)
    parents = model.body_parentid
    fig = plt.figure(figsize=(size[0] / 100, size[1] / 100), dpi=100)
    ax = fig.add_subplot(projection="3d")
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.95)
    with atomic_path(path) as tmp:
        with imageio.get_writer(tmp, fps=motion.fps / stride, codec="libx264", macro_block_size=8,
                                format="FFMPEG") as writer:
            for t in range(0, motion.num_frames, stride):
                data.qpos[:] = motion.qpos[t]
                mujoco.mj_kinematics(model, data)
                ax.cla()
                for b in range(2, model.nbody):  # skip the world and the root's link to it
                    a, c = data.xpos[parents[b]], data.xpos[b]
                    ax.plot([a[0], c[0]], [a[1], c[1]], [a[2], c[2]], color="steelblue", lw=2)
                tp = motion.target_pos[t]
                ax.scatter(tp[:, 0], tp[:, 1], tp[:, 2], color="red", s=6)
                if object_points_local is not None:
                    q = motion.object_quat_wxyz[t]
                    pts = Rotation.from_quat([q[1], q[2], q[3], q[0]]).apply(object_points_local) + motion.object_pos[t]
                    ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], color="darkorange", s=2)
                cx, cy = motion.qpos[t, 0], motion.qpos[t, 1]
                ax.set_xlim(cx - 0.8, cx + 0.8)
                ax.set_ylim(cy - 0.8, cy + 0.8)
                ax.set_zlim(0.0, 1.6)
                ax.set_box_aspect((1, 1, 1))
                ax.set_title(f"frame {t}")
                fig.canvas.draw()
                writer.append_data(np.asarray(fig.canvas.buffer_rgba())[..., :3])
    plt.close(fig)


def write_video(
    motion, cfg, model, path, object_asset=None, backend: str = "auto", stride: int = 1, pretty: bool = False
) -> str:
    """Write the mp4; returns what drew it: "mujoco-egl", "mujoco-osmesa", "mujoco" or "matplotlib".

    backend: "auto" (MuJoCo if its renderer works, else matplotlib), "mujoco" or "matplotlib".
    """
    path = Path(path)
    if backend in ("auto", "mujoco"):
        try:
            render_mujoco(motion, cfg, path, object_asset, stride=stride, pretty=pretty)
            gl = os.environ.get("MUJOCO_GL")
            return f"mujoco-{gl}" if gl else "mujoco"
        except Exception:  # no GL context here (or a driver problem): fall back, unless MuJoCo was demanded
            if backend == "mujoco":
                raise
    points = None if object_asset is None else np.asarray(object_asset.sample_points)
    render_matplotlib(motion, model, path, points, stride=stride)
    return "matplotlib"

"""Offscreen drawing of a clip: the human skeleton, the object and the robot in its default pose beside the human,
all at the same metric scale (matplotlib 3D, Agg). PNG: a strip of keyframes; MP4: the clip (imageio-ffmpeg).

The robot comes from robot_hoi.embodiment (MuJoCo model, default keyframe): it stands `side_offset` metres to
the human's right, follows the human root's xy and heading, and is drawn as its kinematic tree.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import imageio.v2 as imageio
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from deploy.atomic import atomic_path
from robot_hoi.data.clip import HOIClip
from robot_hoi.data.layout import BODY_NAMES, BODY_PARENTS
from robot_hoi.data.objects import to_world
from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.embodiment.mjcf import DEFAULT_KEYFRAME
from robot_hoi.errors import UserError

SIDE_COLOURS = {"L_": "tab:blue", "R_": "tab:red"}
MAX_WIREFRAME_FACES = 500  # draw mesh edges for simple meshes, sample points otherwise
VIEW_HALF_WIDTH_M = 1.2
VIEW_HEIGHT_M = 2.0


@dataclass(frozen=True)
class RobotSkeleton:
    """The robot's body origins (N, 3) in its default pose, root at the world origin facing +x, and the
    (parent, child) index pairs of its kinematic tree."""

    points: np.ndarray
    edges: tuple[tuple[int, int], ...]
    height_m: float


def robot_skeleton(embodiment: str) -> RobotSkeleton:
    cfg = load_embodiment(embodiment)
    model = build_model(cfg)
    data = mujoco.MjData(model)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, DEFAULT_KEYFRAME)
    if key >= 0:
        mujoco.mj_resetDataKeyframe(model, data, key)
    data.qpos[0:2] = 0.0
    data.qpos[3:7] = (1.0, 0.0, 0.0, 0.0)  # wxyz: facing +x
    mujoco.mj_kinematics(model, data)
    edges = tuple(
        (int(model.body_parentid[b]), b) for b in range(1, model.nbody) if model.body_parentid[b] > 0
    )
    return RobotSkeleton(points=np.array(data.xpos), edges=edges, height_m=float(cfg.robot_height))


def heading(body_quat_xyzw: np.ndarray) -> np.ndarray:
    """Yaw (rad) of the pelvis's forward (+x) axis projected on the floor, per frame."""
    forward = Rotation.from_quat(body_quat_xyzw[:, 0]).apply([1.0, 0.0, 0.0])
    return np.arctan2(forward[:, 1], forward[:, 0])


def robot_points(skeleton: RobotSkeleton, clip: HOIClip, frame: int, side_offset: float) -> np.ndarray:
    yaw = Rotation.from_euler("z", heading(clip.body_quat_xyzw[frame : frame + 1])[0])
    base = clip.root_pos[frame] * np.array([1.0, 1.0, 0.0]) + yaw.apply([0.0, -side_offset, 0.0])
    return yaw.apply(skeleton.points) + base


def _object_drawing(clip: HOIClip, frame: int):
    """(points (N, 3) or None, edges (E, 2, 3) or None) of the object at a frame, in world coordinates."""
    obj = clip.object
    pose = (clip.object_pos[frame : frame + 1], clip.object_quat_xyzw[frame : frame + 1])
    if obj is None:
        return clip.object_pos[frame : frame + 1], None
    if len(obj.faces) <= MAX_WIREFRAME_FACES:
        vertices = to_world(obj.vertices, *pose)[0]
        pairs = np.concatenate([obj.faces[:, [0, 1]], obj.faces[:, [1, 2]], obj.faces[:, [2, 0]]])
        pairs = np.unique(np.sort(pairs, axis=1), axis=0)
        return None, vertices[pairs]
    return to_world(obj.sample_points, *pose)[0], None


def draw_frame(ax, clip: HOIClip, frame: int, skeleton: RobotSkeleton | None, side_offset: float) -> None:
    pos = clip.body_pos[frame]
    for j in range(1, len(BODY_NAMES)):
        colour = SIDE_COLOURS.get(BODY_NAMES[j][:2], "0.25")
        seg = pos[[BODY_PARENTS[j], j]]
        ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=colour, lw=1.6)
    points, edges = _object_drawing(clip, frame)
    if points is not None:
        ax.scatter(points[:, 0], points[:, 1], points[:, 2], s=2, color="tab:orange")
    if edges is not None:
        for e in edges:
            ax.plot(e[:, 0], e[:, 1], e[:, 2], color="tab:orange", lw=1.0)
    centre = pos[0].copy()
    if skeleton is not None:
        robot = robot_points(skeleton, clip, frame, side_offset)
        for a, b in skeleton.edges:
            ax.plot(robot[[a, b], 0], robot[[a, b], 1], robot[[a, b], 2], color="tab:green", lw=1.6)
        centre = 0.5 * (centre + robot[0])
    half = VIEW_HALF_WIDTH_M
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(0.0, VIEW_HEIGHT_M)
    ax.set_box_aspect(
        (2.0 * half, 2.0 * half, VIEW_HEIGHT_M)
    )  # aspect = limits: one metric scale on all axes
    # Camera in front of the human and off to its left, so the robot (on its right) stays in view.
    ax.view_init(elev=15.0, azim=float(np.degrees(heading(clip.body_quat_xyzw[frame : frame + 1])[0])) + 35.0)
    ax.set_title(f"t = {frame / clip.fps:.2f} s", fontsize=9)
    ax.tick_params(labelsize=6)


def keyframe_indices(num_frames: int, count: int) -> list[int]:
    return [int(round(i)) for i in np.linspace(0, num_frames - 1, max(1, min(count, num_frames)))]


def render_view(
    clip: HOIClip,
    out: str | Path,
    *,
    embodiment: str | None = "g1_inspire",
    keyframes: int = 6,
    side_offset: float = 1.0,
    video_fps: float = 15.0,
) -> Path:
    """Write a PNG strip of keyframes or an MP4 of the clip. Returns the path."""
    import matplotlib  # here: pyplot (~0.5 s) after choosing the headless Agg backend

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    if out.suffix not in (".png", ".mp4"):
        raise UserError(f"{out}: choose a .png (keyframe strip) or .mp4 (video) output")
    skeleton = robot_skeleton(embodiment) if embodiment else None
    if out.suffix == ".png":
        frames = keyframe_indices(clip.num_frames, keyframes)
        fig = plt.figure(figsize=(3.6 * len(frames), 4.0), dpi=100)
        for k, frame in enumerate(frames):
            ax = fig.add_subplot(1, len(frames), k + 1, projection="3d")
            draw_frame(ax, clip, frame, skeleton, side_offset)
        fig.suptitle(
            f"{clip.name}: human (blue/red), object (orange)" + (", robot (green)" if skeleton else "")
        )
        fig.tight_layout()
        with atomic_path(out) as tmp:
            fig.savefig(tmp, format="png")
        plt.close(fig)
        return out
    return _render_video(clip, out, skeleton, side_offset, video_fps)


def _render_video(clip: HOIClip, out: Path, skeleton, side_offset: float, video_fps: float) -> Path:
    import matplotlib.pyplot as plt  # after render_view's matplotlib.use("Agg")

    stride = max(1, int(round(clip.fps / video_fps)))
    fig = plt.figure(figsize=(6.4, 4.8), dpi=100)
    ax = fig.add_subplot(projection="3d")
    with atomic_path(out) as tmp:
        with imageio.get_writer(
            tmp, format="FFMPEG", fps=clip.fps / stride, codec="libx264", macro_block_size=16
        ) as writer:
            for frame in range(0, clip.num_frames, stride):
                ax.cla()
                draw_frame(ax, clip, frame, skeleton, side_offset)
                fig.canvas.draw()
                writer.append_data(np.asarray(fig.canvas.buffer_rgba())[..., :3])
    plt.close(fig)
    return out

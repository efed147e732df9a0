"""A retargeted robot motion: the robot-space reference the RL teachers track and initialise from.

File format: `NAME.npz` (plain arrays, loaded with allow_pickle=False) plus `NAME.json` next to it (names, fps,
scale, summary). Both are written atomically. Quaternions are MuJoCo's wxyz, so qpos can be copied straight into
MjData.qpos; qvel is MuJoCo's tangent velocity (free joint: world linear, body-frame angular).
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from deploy.atomic import atomic_write_bytes, atomic_write_text
from robot_hoi.errors import DataError

FORMAT_VERSION = 1

# array field -> number of dimensions; leading dim is always T
_ARRAYS = {
    "qpos": 2,
    "qvel": 2,
    "joint_pos": 2,
    "link_pos": 3,
    "link_quat_wxyz": 3,
    "target_pos": 3,
    "object_pos": 2,
    "object_quat_wxyz": 2,
    "anchor": 2,
    "residual": 2,
}
# Arrays a file may lack (older files): the clip's own object path, which is object_pos / object_quat_wxyz where
# nothing moved the object (evaluation reports E_o against it)
_OPTIONAL_ARRAYS = {"source_object_pos": 2, "source_object_quat_wxyz": 2}


@dataclass
class RobotMotion:
    fps: float
    qpos: np.ndarray  # (T, nq): free base pos (3) + quat wxyz (4) + every model joint (fingers included)
    qvel: np.ndarray  # (T, nv) central finite differences (one-sided at the ends)
    joint_pos: np.ndarray  # (T, A) actuated joint positions in actuator (policy) order
    link_pos: np.ndarray  # (T, L, 3) achieved positions of the link_map links (body origin or site)
    link_quat_wxyz: np.ndarray  # (T, L, 4)
    target_pos: np.ndarray  # (T, L, 3) IK targets: the mapped human joints, aimed at each link's landmark
    object_pos: np.ndarray  # (T, 3) robot-space object pose
    object_quat_wxyz: np.ndarray  # (T, 4)
    anchor: np.ndarray  # (T, L) anchor weights from the targets
    residual: np.ndarray  # (T, L) |landmark - target| in metres (landmarks.py; = link_pos where none is set)
    link_names: tuple[str, ...]
    human_names: tuple[str, ...]
    actuator_names: tuple[str, ...]
    embodiment: str
    scale: float
    meta: dict = field(default_factory=dict)  # free-form: source clip, solver settings, report
    # the clip's own robot-space object path, before anything the retarget changed for its contacts (T, 3) / (T, 4);
    # None: object_pos / object_quat_wxyz
    source_object_pos: np.ndarray | None = None
    source_object_quat_wxyz: np.ndarray | None = None

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    def __post_init__(self) -> None:
        T = self.qpos.shape[0]
        if self.source_object_pos is None:
            self.source_object_pos = np.array(self.object_pos, copy=True)
        if self.source_object_quat_wxyz is None:
            self.source_object_quat_wxyz = np.array(self.object_quat_wxyz, copy=True)
        for name, ndim in {**_ARRAYS, **_OPTIONAL_ARRAYS}.items():
            arr = getattr(self, name)
            if arr.ndim != ndim or arr.shape[0] != T:
                raise DataError(f"RobotMotion.{name}: shape {arr.shape} does not fit {T} frames")
        L = len(self.link_names)
        for name in ("link_pos", "link_quat_wxyz", "target_pos", "anchor", "residual"):
            if getattr(self, name).shape[1] != L:
                raise DataError(f"RobotMotion.{name}: {getattr(self, name).shape[1]} links, names list {L}")
        if self.joint_pos.shape[1] != len(self.actuator_names):
            raise DataError(
                f"RobotMotion.joint_pos has {self.joint_pos.shape[1]} columns for {len(self.actuator_names)} actuators")

    def save(self, path: str | Path) -> tuple[Path, Path]:
        """Write NAME.npz and NAME.json; returns both paths."""
        path = Path(path)
        if path.suffix != ".npz":
            raise DataError(f"{path}: motion files end in .npz")
        buf = io.BytesIO()
        np.savez_compressed(buf, **{k: np.asarray(getattr(self, k), dtype=np.float32 if k != "qpos" else np.float64)
                                    for k in {**_ARRAYS, **_OPTIONAL_ARRAYS}})
        atomic_write_bytes(path, buf.getvalue())
        side = path.with_suffix(".json")
        sidecar = {
            "format_version": FORMAT_VERSION,
            "fps": self.fps,
            "num_frames": self.num_frames,
            "embodiment": self.embodiment,
            "scale": self.scale,
            "quaternion_convention": "wxyz",
            "link_names": list(self.link_names),
            "human_names": list(self.human_names),
            "actuator_names": list(self.actuator_names),
            "meta": self.meta,
        }
        atomic_write_text(side, json.dumps(sidecar, indent=1) + "\n")
        return path, side

    @classmethod
    def load(cls, path: str | Path) -> RobotMotion:
        path = Path(path)
        side = path.with_suffix(".json")
        for p in (path, side):
            if not p.is_file():
                raise DataError(f"{p}: no such motion file (a motion is NAME.npz + NAME.json)")
        try:
            sidecar = json.loads(side.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DataError(f"{side}: not valid JSON ({exc})") from exc
        if sidecar.get("format_version") != FORMAT_VERSION:
            raise DataError(f"{side}: format_version {sidecar.get('format_version')!r}, expected {FORMAT_VERSION}")
        try:
            with np.load(path, allow_pickle=False) as npz:
                missing = [k for k in _ARRAYS if k not in npz.files]
                if missing:
                    raise DataError(f"{path}: missing arrays {', '.join(missing)}")
                arrays = {k: np.asarray(npz[k], dtype=np.float64) for k in _ARRAYS}
                arrays |= {k: np.asarray(npz[k], dtype=np.float64) for k in _OPTIONAL_ARRAYS if k in npz.files}
        except (OSError, ValueError) as exc:
            raise DataError(f"{path}: not a readable npz motion file ({exc})") from exc
        try:
            return cls(
                fps=float(sidecar["fps"]),
                link_names=tuple(sidecar["link_names"]),
                human_names=tuple(sidecar["human_names"]),
                actuator_names=tuple(sidecar["actuator_names"]),
                embodiment=str(sidecar["embodiment"]),
                scale=float(sidecar["scale"]),
                meta=dict(sidecar.get("meta", {})),
                **arrays,
            )
        except KeyError as exc:
            raise DataError(f"{side}: missing key {exc}") from exc


def finite_difference_qvel(model, qpos: np.ndarray, fps: float) -> np.ndarray:
    """(T, nq) -> (T, nv): central differences on the configuration manifold (mj_differentiatePos)."""
    T = qpos.shape[0]
    qvel = np.zeros((T, model.nv))
    if T < 2:
        return qvel
    dt = 1.0 / fps
    for t in range(T):
        a, b = max(t - 1, 0), min(t + 1, T - 1)
        mujoco.mj_differentiatePos(model, qvel[t], (b - a) * dt, qpos[a], qpos[b])
    return qvel

"""Reference motion sidecar (`NAME.motion.npz`) the policy tracks, loaded without pickle.

Arrays (world frame, z up, one row per policy step):
    fps               ()        frames per second (= 1 / control_dt of the policy)
    joint_pos         (T, A)    rad, actuator order of the contract (hand joints in rad)
    root_pos          (T, 3)    m, pelvis
    root_quat_wxyz    (T, 4)    pelvis orientation
    link_pos          (T, L, 3) m, the contract's link_names
    object_pos        (T, 3)    m
    object_quat_wxyz  (T, 4)
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from deploy.atomic import atomic_write_bytes
from deploy.contract import PolicyContract
from deploy.errors import DeployError

MOTION_KEYS = ("fps", "joint_pos", "root_pos", "root_quat_wxyz", "link_pos", "object_pos", "object_quat_wxyz")


@dataclass(frozen=True, eq=False)
class ReferenceMotion:
    fps: float
    joint_pos: np.ndarray
    root_pos: np.ndarray
    root_quat_wxyz: np.ndarray
    link_pos: np.ndarray
    object_pos: np.ndarray
    object_quat_wxyz: np.ndarray
    source: str = "<memory>"

    @property
    def num_frames(self) -> int:
        return self.joint_pos.shape[0]

    @property
    def duration_s(self) -> float:
        return self.num_frames / self.fps

    def frame_index(self, t: int) -> int:
        """Tick index -> frame, clamped to [0, T-1] (the reference holds its last frame)."""
        return min(max(int(t), 0), self.num_frames - 1)

    def save(self, path: str | os.PathLike) -> None:
        buffer = io.BytesIO()
        np.savez(buffer, **{key: np.asarray(getattr(self, key)) for key in MOTION_KEYS})
        atomic_write_bytes(path, buffer.getvalue())

    def check_against(self, contract: PolicyContract) -> None:
        """The motion must have the contract's actuator and link counts and run at its control rate."""
        if self.joint_pos.shape[1] != contract.num_actions:
            raise DeployError(
                f"{self.source}: joint_pos has {self.joint_pos.shape[1]} columns but {contract.source} has "
                f"{contract.num_actions} actuators"
            )
        if self.link_pos.shape[1] != len(contract.link_names):
            raise DeployError(
                f"{self.source}: link_pos has {self.link_pos.shape[1]} links but {contract.source} lists "
                f"{len(contract.link_names)} link_names"
            )
        if not math.isclose(1.0 / self.fps, contract.control_dt, rel_tol=1e-4):
            raise DeployError(
                f"{self.source}: fps {self.fps} does not match the policy's control_dt {contract.control_dt} s"
            )


def file_sha256(path: str | os.PathLike) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def load_motion(path: str | os.PathLike, expected_sha256: str | None = None) -> ReferenceMotion:
    path = Path(path)
    if not path.is_file():
        raise DeployError(f"{path}: motion file not found")
    if expected_sha256 is not None and file_sha256(path) != expected_sha256:
        raise DeployError(f"{path}: sha256 does not match the one recorded in the policy (wrong or edited sidecar)")
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in MOTION_KEYS if k not in npz.files]
            if missing:
                raise DeployError(f"{path}: missing array(s) {', '.join(missing)}")
            raw = {k: np.asarray(npz[k]) for k in MOTION_KEYS}
    except (ValueError, OSError, zipfile.BadZipFile) as exc:
        raise DeployError(f"{path}: not a readable motion npz ({exc})") from None

    if raw["fps"].shape != () or not np.isfinite(raw["fps"]) or float(raw["fps"]) <= 0:
        raise DeployError(f"{path}: fps must be a positive scalar")
    arrays = {}
    for key in MOTION_KEYS[1:]:
        a = raw[key]
        if a.dtype.kind not in "fi":
            raise DeployError(f"{path}: {key} must be numeric, got dtype {a.dtype}")
        arrays[key] = a.astype(np.float64)
    num_frames = arrays["joint_pos"].shape[0] if arrays["joint_pos"].ndim == 2 else -1
    expected = {
        "joint_pos": (num_frames, None),
        "root_pos": (num_frames, 3),
        "root_quat_wxyz": (num_frames, 4),
        "link_pos": (num_frames, None, 3),
        "object_pos": (num_frames, 3),
        "object_quat_wxyz": (num_frames, 4),
    }
    if num_frames < 1:
        raise DeployError(f"{path}: joint_pos must be (T, A) with T >= 1, got shape {arrays['joint_pos'].shape}")
    for key, shape in expected.items():
        a = arrays[key]
        if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape, strict=True)):
            want = "(" + ", ".join("T" if i == 0 else ("*" if s is None else str(s)) for i, s in enumerate(shape)) + ")"
            raise DeployError(f"{path}: {key} has shape {a.shape}, expected {want} with T = {num_frames}")
        if not np.all(np.isfinite(a)):
            raise DeployError(f"{path}: {key} has non-finite values")
    for key in ("root_quat_wxyz", "object_quat_wxyz"):
        norms = np.linalg.norm(arrays[key], axis=1)
        if np.any(norms < 0.5) or np.any(norms > 1.5):
            raise DeployError(f"{path}: {key} is not a unit quaternion in frame {int(np.argmax(np.abs(norms - 1)))}")
        arrays[key] = arrays[key] / norms[:, None]
    return ReferenceMotion(fps=float(raw["fps"]), source=str(path), **arrays)


def load_sidecar(contract: PolicyContract, skill: str | None = None, hint: str = "") -> ReferenceMotion | None:
    """The policy's sidecar next to its file: skill `skill`'s (contract.skills), else the default reference; checked
    against the sha256 the policy records. None when the policy names none. A missing file is a DeployError naming
    it, `hint` (what to pass instead) appended to the default reference's."""
    if skill is not None:
        path, info = contract.skill_reference(skill)
        missing = f"the sidecar {path} of skill {skill!r} is missing"
    elif contract.reference is not None:
        path, info = contract.reference_path(), contract.reference
        missing = f"reference sidecar {path} is missing{hint}"
    else:
        return None
    if not path.is_file():
        raise DeployError(f"{contract.source}: {missing}")
    return load_motion(path, expected_sha256=info.sha256)

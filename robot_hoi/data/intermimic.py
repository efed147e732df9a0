"""InterMimic `.pt` clips (one float32 (T, 591) tensor) -> HOIClip fields, column by column (see layout.py)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from robot_hoi.data import layout as L
from robot_hoi.data.clip import HOIClip
from robot_hoi.data.torch_zip import read_torch_tensor
from robot_hoi.errors import DataError

NAME_PATTERN = re.compile(r"^(sub\d+)_([A-Za-z0-9]+)_(\d+)$")
LICENSE = (
    "CC BY-NC-SA 4.0 (OMOMO motion as processed by InterAct/InterMimic): research and non-commercial use "
    "only, attribution required (cite OMOMO, InterAct, InterMimic), derivatives under the same license"
)


def parse_clip_name(stem: str) -> tuple[str | None, str | None]:
    """`sub3_largebox_003` -> ("sub3", "largebox"); anything else -> (None, None)."""
    match = NAME_PATTERN.match(stem)
    return (match.group(1), match.group(2)) if match else (None, None)


def read_intermimic_matrix(path: str | Path) -> np.ndarray:
    """The (T, 591) matrix of an InterMimic `.pt` file (float32, read-only), read without unpickling."""
    raw = read_torch_tensor(path)
    if raw.ndim != 2 or raw.shape[1] != L.NUM_COLUMNS:
        raise DataError(
            f"{path}: expected a (T, {L.NUM_COLUMNS}) InterMimic clip tensor, got shape {raw.shape}"
        )
    if raw.dtype.kind != "f":
        raise DataError(f"{path}: expected a floating-point tensor, got {raw.dtype}")
    return raw


def clip_from_matrix(raw: np.ndarray, *, name: str, fps: float = L.CLIP_FPS) -> HOIClip:
    """Split the columns into HOIClip arrays (float64 copies). Object asset, height and inferred contacts are
    left empty for the reader to fill in."""
    x = np.asarray(raw, dtype=np.float64)
    num_frames = x.shape[0]
    subject, object_name = parse_clip_name(name)
    return HOIClip(
        name=name,
        fps=float(fps),
        root_pos=x[:, L.ROOT_POS].copy(),
        root_quat_xyzw=x[:, L.ROOT_QUAT_XYZW].copy(),
        dof_rotvec=x[:, L.DOF_ROTVEC].reshape(num_frames, L.NUM_JOINTS, 3).copy(),
        body_pos=x[:, L.BODY_POS].reshape(num_frames, L.NUM_BODIES, 3).copy(),
        body_quat_xyzw=x[:, L.BODY_QUAT_XYZW].reshape(num_frames, L.NUM_BODIES, 4).copy(),
        object_pos=x[:, L.OBJECT_POS].copy(),
        object_quat_xyzw=x[:, L.OBJECT_QUAT_XYZW].copy(),
        contact=np.where(np.isfinite(x[:, L.CONTACT]), x[:, L.CONTACT], 0).round().astype(np.int8),
        body_contact=np.nan_to_num(x[:, L.BODY_CONTACT]).round().astype(np.int8),
        inferred_contact=np.zeros(num_frames, dtype=bool),
        inferred_body_contact=np.zeros((num_frames, L.NUM_BODIES), dtype=np.int8),
        object_name=object_name or "",
        subject=subject,
        source=f"InterMimic/InterAct hoi_data clip {name}.pt (OMOMO motion capture)",
        license=LICENSE,
    )


def check_label_values(raw: np.ndarray, path: str | Path) -> None:
    """Contact columns must hold the documented label values (checked before rounding to int8)."""
    flags = raw[:, L.CONTACT]
    labels = raw[:, L.BODY_CONTACT]
    if not np.isin(flags[np.isfinite(flags)], (0.0, 1.0)).all():
        raise DataError(f"{path}: contact flag column {L.CONTACT} holds values other than 0/1")
    if not np.isin(labels[np.isfinite(labels)], (-1.0, 0.0, 1.0)).all():
        raise DataError(f"{path}: body contact labels (columns 331:383) hold values other than -1/0/+1")

"""Evaluation metrics, as pure numpy functions of simulated and reference trajectories.

InterMimic (Sec. 4), computed as robot_hoi/tasks/interaction/env.py does in training:
    E_h   per-link position error (cm) over the body links (hand links excluded, as for OMOMO), averaged over
          the links, then over the frames the imitation lasted;
    E_o   per-point position error (cm) between the simulated and the reference object's surface samples,
          averaged the same way;
    success: the clip's last frame is reached without an early termination (Sec. 3.2 / supp. E.1 thresholds);
    duration: seconds the imitation lasted before a termination (the whole clip on success).
ComplexMimic (supp. F, Eqs. 14-17), over the same body links J and frames T (positions p, reference p^):
    E_g-mpjpe = 1/(TJ) sum_t sum_j |p_tj - p^_tj|                                 (mm)
    E_mpjpe   = 1/(TJ) sum |(p_tj - p_t,root) - (p^_tj - p^_t,root)|               (mm)
    E_acc     = 1/((T-2)J) sum_{t=2}^{T-1} |a_tj - a^_tj|, a_t = p_{t+1} - 2 p_t + p_{t-1}   (mm/frame^2)
    E_vel     = 1/((T-1)J) sum_{t=1}^{T-1} |v_tj - v^_tj|, v_t = p_{t+1} - p_t              (mm/frame)
"""

from __future__ import annotations

import numpy as np

from robot_hoi import termination
from robot_hoi.termination import interaction_weights  # noqa: F401  (re-exported: sim2sim's callers use it)

HAND_LINK_MARKERS = ("_tip", "hand_base")  # = robot_hoi.tasks.interaction.scene_setup (E_h excludes these)
EPS = 1e-4


def body_link_indices(link_names) -> list[int]:
    return [i for i, n in enumerate(link_names) if not any(m in n for m in HAND_LINK_MARKERS)]


def subsample_points(points: np.ndarray, count: int) -> np.ndarray:
    """Evenly strided subset (deterministic), as training's env does for its object surface samples."""
    if count <= 0 or len(points) <= count:
        return np.asarray(points, dtype=np.float64)
    return np.asarray(points, dtype=np.float64)[np.round(np.linspace(0, len(points) - 1, count)).astype(int)]


def quat_wxyz_to_matrices(quat_wxyz: np.ndarray) -> np.ndarray:
    """(..., 4) wxyz -> (..., 3, 3)."""
    q = np.asarray(quat_wxyz, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def object_points_world(points_local: np.ndarray, pos: np.ndarray, quat_wxyz: np.ndarray) -> np.ndarray:
    """Local surface points (P, 3) in object poses (..., 3)/(..., 4) -> (..., P, 3)."""
    rot = quat_wxyz_to_matrices(quat_wxyz)
    return np.einsum("...ij,pj->...pi", rot, points_local) + np.asarray(pos)[..., None, :]


def nearest_surface_vectors(link_pos: np.ndarray, points_world: np.ndarray) -> np.ndarray:
    """Vectors from each link to its nearest surface point: (..., L, 3), (..., P, 3) -> (..., L, 3)."""
    link_pos = np.asarray(link_pos, dtype=np.float64)
    points_world = np.asarray(points_world, dtype=np.float64)
    # |p - x|^2 = |p|^2 - 2 p.x + |x|^2, one matrix product instead of an (L, P, 3) difference array
    d2 = ((points_world * points_world).sum(-1)[..., None, :] - 2.0 * link_pos @ np.swapaxes(points_world, -1, -2)
          + (link_pos * link_pos).sum(-1)[..., :, None])
    nearest = np.take_along_axis(points_world, d2.argmin(-1)[..., None], axis=-2)
    return nearest - link_pos


def interaction_distance_error(d: np.ndarray, d_hat: np.ndarray) -> np.ndarray:
    """|<w_d, |d|> - <w_d, |d_hat|>|, the interaction early-termination quantity (Sec. 3.2)."""
    return termination.interaction_distance_error(interaction_weights(d, d_hat), d, d_hat)


def mean_position_error(pos: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(T, J, 3) x2 -> (T,) mean over J of |p - p^| (m)."""
    return termination.mean_link_error(np.asarray(pos), np.asarray(ref))


def mpjpe_global(pos: np.ndarray, ref: np.ndarray) -> float:
    """ComplexMimic Eq. 14, in the units of the inputs."""
    return float(np.linalg.norm(pos - ref, axis=-1).mean())


def mpjpe_root_relative(pos: np.ndarray, ref: np.ndarray, root: int) -> float:
    """ComplexMimic Eq. 15: positions relative to joint `root` in each frame."""
    rel = pos - pos[:, root: root + 1]
    rel_ref = ref - ref[:, root: root + 1]
    return float(np.linalg.norm(rel - rel_ref, axis=-1).mean())


def acceleration_error(pos: np.ndarray, ref: np.ndarray) -> float:
    """ComplexMimic Eq. 16 (per frame^2, in the units of the inputs); nan with fewer than 3 frames."""
    if len(pos) < 3:
        return float("nan")
    acc = pos[2:] - 2 * pos[1:-1] + pos[:-2]
    acc_ref = ref[2:] - 2 * ref[1:-1] + ref[:-2]
    return float(np.linalg.norm(acc - acc_ref, axis=-1).mean())


def velocity_error(pos: np.ndarray, ref: np.ndarray) -> float:
    """ComplexMimic Eq. 17 (per frame); nan with fewer than 2 frames."""
    if len(pos) < 2:
        return float("nan")
    return float(np.linalg.norm(np.diff(pos, axis=0) - np.diff(ref, axis=0), axis=-1).mean())


def tracking_metrics(link_pos: np.ndarray, ref_link_pos: np.ndarray, object_err_m: np.ndarray,
                     body_links: list[int], root: int, tracked: np.ndarray | None = None) -> dict[str, float]:
    """All tracking errors of one episode from its evaluated frames (T, L, 3) and per-frame object error (T,).
    E_h_max_cm / E_o_max_cm: the worst per-frame errors over the `tracked` frames (bool (T,); all when None), as
    training's interaction success reads them (after the warmup)."""
    nan = float("nan")
    if len(link_pos) == 0:
        return {"E_h_cm": nan, "E_o_cm": nan, "E_h_max_cm": nan, "E_o_max_cm": nan, "mpjpe_g_mm": nan,
                "mpjpe_mm": nan, "e_acc_mm": nan, "e_vel_mm": nan}
    pos, ref = link_pos[:, body_links], ref_link_pos[:, body_links]
    root_in_body = body_links.index(root)
    tracked = np.ones(len(pos), dtype=bool) if tracked is None else np.asarray(tracked, dtype=bool)
    body_err = mean_position_error(pos, ref)
    object_err = np.asarray(object_err_m, dtype=np.float64)
    return {
        "E_h_max_cm": 100.0 * float(body_err[tracked].max()) if tracked.any() else nan,
        "E_o_max_cm": 100.0 * float(object_err[tracked].max()) if tracked.any() else nan,
        "E_h_cm": 100.0 * float(body_err.mean()),
        "E_o_cm": 100.0 * float(object_err.mean()),
        "mpjpe_g_mm": 1000.0 * mpjpe_global(pos, ref),
        "mpjpe_mm": 1000.0 * mpjpe_root_relative(pos, ref, root_in_body),
        "e_acc_mm": 1000.0 * acceleration_error(pos, ref),
        "e_vel_mm": 1000.0 * velocity_error(pos, ref),
    }


def hand_command_stats(commanded: np.ndarray, measured: np.ndarray, forces: np.ndarray) -> dict[str, float]:
    """Statistics of the hands over the policy ticks: commanded / measured ANGLE units (T, 12), FORCE_ACT grams.

    mean_command: average ANGLE_SET (1000 = open); command_step: mean |change| per tick (chatter);
    closed_fraction / open_fraction: share of channel-ticks commanded at <= 50 / >= 950 units;
    tracking_error: mean |ANGLE_SET(t-1) - ANGLE_ACT(t)| (the reading arrives one tick after the write);
    peak_force_g / mean_force_g: FORCE_ACT.
    """
    commanded = np.asarray(commanded, dtype=np.float64)
    valid = np.all(commanded >= 0, axis=1)  # -1: the runtime sent no hand command that tick
    c, m, f = commanded[valid], np.asarray(measured, np.float64)[valid], np.asarray(forces, np.float64)[valid]
    if len(c) == 0:
        return {k: float("nan") for k in ("mean_command", "command_step", "closed_fraction", "open_fraction",
                                          "tracking_error", "peak_force_g", "mean_force_g")}
    return {
        "mean_command": float(c.mean()),
        "command_step": float(np.abs(np.diff(c, axis=0)).mean()) if len(c) > 1 else 0.0,
        "closed_fraction": float((c <= 50).mean()),
        "open_fraction": float((c >= 950).mean()),
        "tracking_error": float(np.abs(c[:-1] - m[1:]).mean()) if len(c) > 1 else float("nan"),
        "peak_force_g": float(f.max()),
        "mean_force_g": float(f.mean()),
    }


def percentiles_ms(values_s, qs=(50, 99)) -> dict[str, float | None]:
    arr = np.asarray(values_s, dtype=np.float64)
    if arr.size == 0:
        return {**{f"p{q}": None for q in qs}, "max": None}
    return {**{f"p{q}": float(np.percentile(arr, q)) * 1e3 for q in qs}, "max": float(arr.max()) * 1e3}


def aggregate(values) -> dict[str, float | None]:
    """mean / std / min / max of finite values (None when there are none)."""
    arr = np.asarray([v for v in values if v is not None], dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    if arr.size == 0:
        return {"mean": None, "std": None, "min": None, "max": None, "n": 0}
    return {"mean": float(arr.mean()), "std": float(arr.std()), "min": float(arr.min()), "max": float(arr.max()),
            "n": int(arr.size)}

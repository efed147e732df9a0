"""ComplexMimic's scene perception (Sec. 3.1): a height map of 20 x 20 samples on a square grid centred on the
character and aligned with its heading, 8 cm apart.

The scene here is the floor (z = 0) and the object, simulated as the convex hull of its mesh
(robot_hoi.sim.scene.add_object): each sample is a vertical ray against the hull's triangles, and the height is
the top surface under it (world z, floor 0). Grid axes: x forward, y left of the robot's heading.
"""

from __future__ import annotations

import numpy as np
import torch
import trimesh
from torch import Tensor

from robot_hoi.utils.torch_rot import quat_apply, yaw_quat

_EPS = 1e-9


def grid_offsets(size: int, spacing: float) -> Tensor:
    """(size * size, 2) sample offsets in the heading frame, centred on the robot: x varies fastest."""
    axis = (torch.arange(size, dtype=torch.float32) - (size - 1) / 2.0) * spacing
    gy, gx = torch.meshgrid(axis, axis, indexing="ij")
    return torch.stack([gx.reshape(-1), gy.reshape(-1)], dim=-1)


def top_surface_heights(points_xy: Tensor, triangles: Tensor, floor: float = 0.0) -> Tensor:
    """Height of the highest triangle above each point (vertical rays), at least `floor`.

    points_xy (N, G, 2), triangles (N, F, 3, 3) -> (N, G). A point inside a triangle's xy projection (barycentric
    coordinates l_i >= 0) gets z = sum_i l_i z_i; triangles seen edge-on (zero projected area) are skipped.
    """
    v0, v1, v2 = triangles[..., 0, :], triangles[..., 1, :], triangles[..., 2, :]  # (N, F, 3)
    px, py = points_xy[..., 0][:, :, None], points_xy[..., 1][:, :, None]  # (N, G, 1)
    x0, y0, z0 = (v0[..., i][:, None, :] for i in range(3))  # (N, 1, F)
    x1, y1, z1 = (v1[..., i][:, None, :] for i in range(3))
    x2, y2, z2 = (v2[..., i][:, None, :] for i in range(3))
    det = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
    ok = det.abs() > _EPS
    safe = torch.where(ok, det, torch.ones_like(det))
    l0 = ((y1 - y2) * (px - x2) + (x2 - x1) * (py - y2)) / safe
    l1 = ((y2 - y0) * (px - x2) + (x0 - x2) * (py - y2)) / safe
    l2 = 1.0 - l0 - l1
    inside = ok & (l0 >= -1e-6) & (l1 >= -1e-6) & (l2 >= -1e-6)
    z = l0 * z0 + l1 * z1 + l2 * z2
    top = torch.where(inside, z, torch.full_like(z, -torch.inf)).amax(dim=-1)
    return top.clamp(min=floor)


def hull_triangles(vertices: np.ndarray, faces: np.ndarray) -> Tensor:
    """(F, 3, 3) triangles of the convex hull the simulation uses for the object, in the object frame."""
    hull = trimesh.Trimesh(vertices=vertices, faces=faces, process=True).convex_hull
    return torch.tensor(np.array(hull.triangles), dtype=torch.float32)


class HeightMap:
    """Observation provider (student_env.ObservationProvider): (N, size^2) heights around each robot."""

    def __init__(self, object_asset, size: int = 20, spacing: float = 0.08) -> None:
        self.offsets = grid_offsets(size, spacing)
        self.triangles = hull_triangles(np.asarray(object_asset.vertices), np.asarray(object_asset.faces))
        self.dim = size * size

    def heights(self, root_pos: Tensor, root_quat_wxyz: Tensor, object_pos: Tensor, object_quat_wxyz: Tensor
                ) -> Tensor:
        if self.offsets.device != root_pos.device:  # once: the grid and the hull move to the env's device
            self.offsets, self.triangles = self.offsets.to(root_pos.device), self.triangles.to(root_pos.device)
        heading = yaw_quat(root_quat_wxyz)
        offsets3 = torch.cat([self.offsets, torch.zeros(len(self.offsets), 1, device=root_pos.device)], dim=-1)
        points = quat_apply(heading[:, None], offsets3[None])[..., :2] + root_pos[:, None, :2]
        tri = quat_apply(object_quat_wxyz[:, None, None], self.triangles[None]) + object_pos[:, None, None]
        return top_surface_heights(points, tri)

    def __call__(self, env, obs=None, reset=None) -> Tensor:
        return self.heights(env.root_pos, env.root_quat, env.object_pos, env.object_quat)

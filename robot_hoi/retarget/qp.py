"""Retarget as constrained optimisation: per frame a sequence of quadratic programs in the joint step dq.

    min_dq  w_mesh |A (p + J dq - p_hat)|^2                       interaction mesh (Laplacian deformation)
            + w_pos sum_i w_i |p_i + J_i dq - p_hat_i|^2          keypoints at their targets
            + w_root |rot err + J_r dq|^2 + mu |q + dq - q_default|^2 + lambda |dq|^2
    s.t.    joint position limits, joint speed <= max_joint_speed (per frame), |dq| <= max_step   (bounds)
            probe spheres (hands and arms) outside the object's convex pieces           (linearised, hard)
            sole points and hand probes above the floor                                  (linearised, hard)
            a stance foot within foot_tolerance of where it landed                       (linearised, hard)

over the floating base and the body joints (the fingers are set by the caller, as for the damped least-squares IK
in ik.py). p are the keypoints (the link landmarks), p_hat their targets: the scaled body, anchored to the real-size
object near it (targets.py). The interaction mesh (OmniRetarget) is a Delaunay tetrahedralisation of the targets
and object surface samples; each vertex's Laplacian coordinate (itself minus the mean of its neighbours) is kept
as in the targets. The object is given, so its points do not move and the residual reduces to A (p - p_hat), A
the keypoint columns of the Laplacian: an error shared by neighbouring keypoints and the object costs little, one
that changes where a keypoint sits relative to them costs a lot.

Each frame is warm-started from the previous one and its steps together move no joint faster than
max_joint_speed, so the track is smooth because of the limits, without filters afterwards. A QP the constraints
make infeasible (e.g. a probe deeper than a speed-limited step can clear) is solved again with the stance rows
dropped, then with the penetration rows only forbidding deeper contact; such frames are counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import qpsolvers
from scipy.spatial import Delaunay, QhullError

from robot_hoi.retarget.ik import IKResult, IKSolver
from robot_hoi.retarget.kinematics import apply_joint_couplings, forward, link_positions, point_jacobians


@dataclass(frozen=True)
class QPSettings:
    iterations: int = 3              # QPs per frame after the first, warm-started from the previous frame
    first_frame_iterations: int = 60
    mesh_weight: float = 4.0         # interaction-mesh Laplacian rows
    position_weight: float = 1.0     # x the targets' per-link weights: keypoints at their targets
    object_points: int = 48          # object surface samples in the interaction mesh
    posture_weight: float = 1e-3     # pull toward the default pose in directions the targets leave free
    damping: float = 1e-4
    max_joint_speed: float = 12.0    # rad/s, every body joint, hard
    max_step: float = 0.3            # trust region of one QP (rad or m)
    contact_distance: float = 0.05   # m: probes and sole points this close to the object or floor get a row
    # m the linearised rows keep probe spheres off the object: a step of up to max_joint_speed / fps bends the
    # arm enough that a sphere kept exactly on the surface ended 5-9 mm inside it (embedded:lift_place, 30 fps)
    object_clearance: float = 0.006
    foot_tolerance: float = 0.001    # m (position) and rad (orientation) a stance foot may move from its landing
    solver: str = "daqp"             # qpsolvers backend
    # rad or m: a frame's iterations stop once no coordinate moves more than this in one (converged); larger
    # values save few iterations: the per-iteration speed limit binds on most frames (docs/experiments/retarget_gate.md)
    step_tolerance: float = 1e-6


class QPRetargeter:
    """Frame-by-frame constrained IK on the geometry of an IKSolver (its keypoints, limits, soles and probes)."""

    def __init__(self, ik: IKSolver, settings: QPSettings | None = None):
        self.ik = ik
        self.model, self.data = ik.model, ik.data  # the IK's probe, sole and root helpers read its data
        self.settings = settings or QPSettings()
        n = len(ik.dofs)
        self.n = n
        self.free_cols = np.arange(6) if ik.free_joint is not None else np.zeros(0, dtype=np.int64)
        self.joint_cols = np.setdiff1d(np.arange(n), self.free_cols)
        self.fallbacks = 0

    # -- one QP -----------------------------------------------------------------------------------------------

    def _step(self, q: np.ndarray, t: int, targets: np.ndarray, weights: np.ndarray, mesh: np.ndarray,
              speed_step: float | None, root_quat: np.ndarray | None, pins: dict) -> np.ndarray:
        ik, s, m, d = self.ik, self.settings, self.model, self.data
        d.qpos[:] = q
        forward(m, d)
        pos = link_positions(d, ik.points)
        jac = np.zeros((len(pos), 3, m.nv))
        point_jacobians(m, d, ik.points.body_ids, pos, jac)
        J = jac[:, :, ik.dofs]  # (L, 3, n)
        err = targets - pos
        # keypoints: sum_i w_i |J_i dq - err_i|^2
        w = s.position_weight * np.repeat(weights, 3)
        Jf = J.reshape(-1, self.n)
        H = Jf.T @ (Jf * w[:, None])
        c = -Jf.T @ (err.reshape(-1) * w)
        if s.mesh_weight > 0 and mesh.size:  # |A (J dq - err)|^2, per axis
            AJ = np.einsum("nl,lkj->nkj", mesh, J).reshape(-1, self.n)
            Ae = (mesh @ err).reshape(-1)
            H += s.mesh_weight * AJ.T @ AJ
            c -= s.mesh_weight * AJ.T @ Ae
        if root_quat is not None and ik.settings.root_rot_weight > 0 and ik.root_body >= 0:
            g_r = np.zeros(self.n)
            ik._add_root_rows(H, g_r, root_quat)  # the IK's weak pull toward the human pelvis orientation
            c -= g_r
        H[np.diag_indices(self.n)] += s.damping
        post = ik._post_col
        H[post, post] += s.posture_weight
        c[post] -= s.posture_weight * (ik.default_qpos[ik._post_qadr] - q[ik._post_qadr])

        lb, ub = np.full(self.n, -s.max_step), np.full(self.n, s.max_step)
        if speed_step is not None:
            lb[self.joint_cols] = np.maximum(lb[self.joint_cols], -speed_step)
            ub[self.joint_cols] = np.minimum(ub[self.joint_cols], speed_step)
        q_lim = q[ik._lim_qadr]
        lb[ik._lim_col] = np.maximum(lb[ik._lim_col], np.minimum(ik._lim_lo - q_lim, 0.0))
        ub[ik._lim_col] = np.minimum(ub[ik._lim_col], np.maximum(ik._lim_hi - q_lim, 0.0))

        rows = [self._object_rows(t), self._floor_rows(), self._stance_rows(pins)]
        for attempt in range(3):
            G, h = _stack(rows, self.n)
            dq = qpsolvers.solve_qp(H, c, G, h, lb=lb, ub=ub, solver=s.solver)
            if dq is not None:
                return dq
            self.fallbacks += 1
            if attempt == 0:
                rows[2] = None  # the stance rows go first
            else:  # penetrating rows only forbid going deeper
                rows = [None if r is None else (r[0], np.maximum(r[1], 0.0)) for r in rows]
        return np.zeros(self.n)

    def _object_rows(self, t: int):
        """-n.J dq <= dist - radius for the probes near the object: the sphere ends outside the pieces."""
        ik = self.ik
        if ik._object is None or ik.probes is None or not len(ik.probes):
            return None
        world, depth, normals = ik._probe_depths(self.settings.contact_distance)  # depth = radius - distance
        near = np.flatnonzero(depth > -self.settings.contact_distance)
        if not len(near):
            return None
        jac = np.zeros((len(near), 3, self.model.nv))
        point_jacobians(self.model, self.data, ik.probes.body_ids[near], world[near], jac)
        Jn = np.einsum("ni,nij->nj", normals[near], jac[:, :, ik.dofs])
        return -Jn, -depth[near] - self.settings.object_clearance

    def _floor_rows(self):
        """-J_z dq <= z - floor for sole points, and z - radius - floor for hand probes, near the floor."""
        ik, s = self.ik, self.settings
        floor = ik.settings.floor_height
        bodies, points, gaps = [], [], []
        if len(ik.sole_body):
            soles = ik._sole_world()
            bodies.append(ik.sole_body)
            points.append(soles)
            gaps.append(soles[:, 2] - floor)
        if ik.probes is not None and len(ik.probes):
            world, depth = ik._hand_floor_depths()  # depth = floor + radius - z (-inf on arm probes)
            bodies.append(ik.probes.body_ids)
            points.append(world)
            gaps.append(-depth)
        if not bodies:
            return None
        bodies, points, gaps = np.concatenate(bodies), np.concatenate(points), np.concatenate(gaps)
        near = np.flatnonzero(gaps < s.contact_distance)
        if not len(near):
            return None
        jac = np.zeros((len(near), 3, self.model.nv))
        point_jacobians(self.model, self.data, bodies[near], points[near], jac)
        return -jac[:, 2, self.ik.dofs], gaps[near]

    def _stance_rows(self, pins: dict):
        """|pose error + J dq| <= foot_tolerance for each pinned foot (position and orientation, both ways)."""
        if not pins:
            return None
        m, d, tol = self.model, self.data, self.settings.foot_tolerance
        G, h = [], []
        jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        for body, (pin_pos, pin_quat) in pins.items():
            mujoco.mj_jacBody(m, d, jp, jr, body)
            rot_err = np.zeros(3)  # world-frame rotation from the pin to the current orientation
            mujoco.mju_subQuat(rot_err, d.xquat[body], pin_quat)
            rot_err = d.xmat[body].reshape(3, 3) @ rot_err
            J = np.vstack([jp, jr])[:, self.ik.dofs]
            e = np.concatenate([d.xpos[body] - pin_pos, rot_err])
            G += [J, -J]
            h += [tol - e, tol + e]
        return np.vstack(G), np.concatenate(h)

    # -- a clip -----------------------------------------------------------------------------------------------

    def solve(self, targets: np.ndarray, weights: np.ndarray, fps: float, preset_qpos: np.ndarray | None = None,
              root_quat_wxyz: np.ndarray | None = None, object_track=None, object_points: np.ndarray | None = None,
              stance: dict[int, np.ndarray] | None = None) -> IKResult:
        """targets (T, L, 3) and weights (T, L) of the keypoints; preset_qpos (T, nq) for the entries the QP does not
        move (fingers); object_track (hull, pos (T, 3), quat_wxyz (T, 4)); object_points (P, 3) surface samples in
        the object frame for the interaction mesh; stance {foot body id: (T,) bool}: frames the foot is planted."""
        ik, s = self.ik, self.settings
        T = targets.shape[0]
        stance = stance or {}
        sample = _subsample(object_points, s.object_points) if object_points is not None else None
        q = ik.initial_qpos(targets[0], None if root_quat_wxyz is None else root_quat_wxyz[0])
        qpos = np.zeros((T, self.model.nq))
        iters = np.zeros(T, dtype=np.int64)
        pins: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for t in range(T):
            if preset_qpos is not None:
                q[ik._preset_qadr] = preset_qpos[t, ik._preset_qadr]
            apply_joint_couplings(self.model, q)
            ik._object = None if object_track is None else ik._object_at(object_track, t)
            points = None
            if sample is not None and object_track is not None:
                _, pos, rot = ik._object_at(object_track, t)
                points = sample @ rot.T + pos
            mesh = interaction_mesh(targets[t], points)
            first = t == 0
            n_it = s.first_frame_iterations if first else s.iterations
            speed = None if first else s.max_joint_speed / fps / n_it
            active = {b: p for b, p in pins.items() if stance[b][t]}
            rq = None if root_quat_wxyz is None else root_quat_wxyz[t]
            for _ in range(n_it):
                dq = self._step(q, t, targets[t], weights[t], mesh, speed, rq, active)
                full = np.zeros(self.model.nv)
                full[ik.dofs] = dq
                mujoco.mj_integratePos(self.model, q, full, 1.0)
                q[ik._lim_qadr] = np.clip(q[ik._lim_qadr], ik._lim_lo, ik._lim_hi)
                iters[t] += 1
                if np.abs(dq).max() < s.step_tolerance:
                    break
            qpos[t] = q
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.model, self.data)
            for body, down in stance.items():  # a foot landing this frame is pinned where it is now
                if down[t] and body not in active:
                    pins[body] = (self.data.xpos[body].copy(), self.data.xquat[body].copy())
                elif not down[t]:
                    pins.pop(body, None)
        ik._object = None
        return ik.evaluate(qpos, targets, iters, object_track)


def interaction_mesh(keypoints: np.ndarray, object_points: np.ndarray | None) -> np.ndarray:
    """(N, L) keypoint columns of the uniform Laplacian of the Delaunay tetrahedralisation of the keypoints (L, 3)
    and the object points (P, 3): row i gives vertex i's Laplacian coordinate as a combination of the keypoints
    (the object points' columns are dropped: they do not move). Empty when the mesh cannot be built."""
    verts = keypoints if object_points is None else np.vstack([keypoints, object_points])
    n, L = len(verts), len(keypoints)
    try:
        simplices = Delaunay(verts).simplices
    except (QhullError, ValueError):
        return np.zeros((0, L))
    adj = np.zeros((n, n), dtype=bool)
    for a in range(simplices.shape[1]):
        for b in range(simplices.shape[1]):
            if a != b:
                adj[simplices[:, a], simplices[:, b]] = True
    lap = np.eye(n) - adj / np.maximum(adj.sum(1, keepdims=True), 1)
    touches = lap[:, :L].any(1)  # rows that involve a keypoint
    return lap[touches][:, :L]


def _subsample(points: np.ndarray, count: int) -> np.ndarray:
    """`count` of the points spread out by farthest-point sampling (deterministic: starts at the first point)."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) <= count:
        return points
    chosen = [0]
    dist = np.linalg.norm(points - points[0], axis=1)
    for _ in range(count - 1):
        chosen.append(int(dist.argmax()))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return points[chosen]


def _stack(rows, n: int):
    rows = [r for r in rows if r is not None]
    if not rows:
        return None, None
    return np.vstack([r[0] for r in rows]).reshape(-1, n), np.concatenate([r[1] for r in rows])

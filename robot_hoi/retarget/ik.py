"""Per-frame damped-least-squares IK on a MuJoCo model: link points to target positions.

Each frame solves, warm-started from the previous frame's answer, a few Gauss-Newton steps of

    min_dq  sum_i w_i |p_i + J_i dq - t_i|^2  +  w_floor sum_{sole points below floor} (z + J_z dq - floor)^2
            + w_root |rot err + J_r dq|^2  +  lambda |dq|^2  +  mu |q + dq - q_default|^2_(IK joints)

over the floating base and the chosen joints (the body joints; the fingers are set by the caller). The last term is
the posture pull: with a damped pseudo-inverse, projecting a pull into the task null space equals adding a small
posture term, so it only wins in directions the link targets leave free (waist twist, wrist roll, elbow swivel).
Joint limits: a step that would cross a limit is clamped there and the remaining joints are re-solved with that
joint held (one active-set pass), then every limited joint is clamped. Feet: link targets on the feet are raised
to at least their flat-foot height, sole points (the foot collision geoms' lowest corners) that sink below the
floor become extra, heavily weighted rows pushing them back up, a foot near the floor is pulled toward zero roll,
and after the last iteration the base is raised by whatever penetration is left, so no sole point ends below it.
Object: given the object's hull and pose per frame, probe points (sphere-swept hand and arm collision geometry,
object_contact.py) that sink into the hull become rows pushing them out along the nearest face normal (the hand
probes already from `object_margin` outside it).
Floor for the hands: hand probes lower than their radius plus `hand_floor_clearance` above the floor become rows
pushing them up (the mocap fingers grip a floor box below its bottom edge, where a robot hand cannot go).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from robot_hoi.errors import DataError
from robot_hoi.retarget.kinematics import (
    apply_joint_couplings,
    forward,
    free_joint_id,
    joint_ids,
    link_positions,
    link_quats_wxyz,
    point_jacobians,
    resolve_links,
)
from robot_hoi.retarget.object_contact import HullPlanes, ProbePoints

_DOFS_PER_JOINT = {
    mujoco.mjtJoint.mjJNT_FREE: 6,
    mujoco.mjtJoint.mjJNT_BALL: 3,
    mujoco.mjtJoint.mjJNT_SLIDE: 1,
    mujoco.mjtJoint.mjJNT_HINGE: 1,
}


IK_SOLVERS = ("dls", "qp")


@dataclass(frozen=True)
class IKSettings:
    iterations: int = 8  # per frame after the first (warm-started)
    first_frame_iterations: int = 150
    damping: float = 1e-4  # lambda, in the units of the weighted squared error (m^2)
    posture_weight: float = 1e-3  # mu: pull of the IK joints toward the default pose
    polish_iterations: int = 2  # the last iterations of a frame run without the posture pull (no bias)
    root_rot_weight: float = 0.02  # weak pull of the root toward a given orientation (when one is given)
    max_step: float = 0.3  # largest change of any coordinate in one iteration (rad or m)
    floor_height: float = 0.0
    floor_weight: float = 50.0
    object_weight: float = 20.0  # pushes hand probe points out of the object's hull
    object_margin: float = 0.01  # m: probes this close to the hull already resist moving in (no chatter)
    # hand probes kept this far above the floor (weighted like the soles): OMOMO hands grip a floor box by its bottom
    # edge with the fingertips at or below the floor; the robot's fingers then hit the floor and the simulated wrists
    # ended 4-6 cm above the reference (sub3_largebox_003), off the grip the squeeze was computed for. < 0: off
    hand_floor_clearance: float = 0.01
    foot_roll_weight: float = 0.05  # keeps a foot near the floor from rolling onto its edge
    foot_roll_height: float = 0.08  # m: the roll term fades out as the sole rises to this height
    step_tolerance: float = 1e-6  # stop a frame's iterations once max |dq| falls below this
    # "dls": this module's damped least squares, then the pipeline's repairs (speed limit, smoothing, push-out
    # passes); "qp": retarget/qp.py, hard limits and contacts in a QP per step, no repairs afterwards
    solver: str = "dls"

    def __post_init__(self) -> None:
        if self.solver not in IK_SOLVERS:
            raise DataError(f"the IK solver must be one of {', '.join(IK_SOLVERS)}, not {self.solver!r}")


@dataclass
class IKResult:
    qpos: np.ndarray  # (T, nq)
    link_pos: np.ndarray  # (T, L, 3) achieved
    link_quat_wxyz: np.ndarray  # (T, L, 4) achieved orientations of the link frames (body or site)
    point_pos: np.ndarray  # (T, L, 3) achieved IK points (the landmarks; = link_pos where none is set)
    residual: np.ndarray  # (T, L) |IK point - target| in metres (target after the foot clamp)
    sole_min_z: np.ndarray  # (T,) lowest sole point; below floor_height means the feet penetrate
    object_penetration: np.ndarray  # (T,) deepest hand probe inside the object's hull (0 when none, or no object)
    hand_floor_depth: np.ndarray  # (T,) deepest hand probe (its sphere) below the floor (0 when none)
    at_limit: np.ndarray  # (T, J_limited) bool, joint sitting on a limit (within 1e-4 rad)
    limited_joint_names: tuple[str, ...]
    iterations: np.ndarray  # (T,) Gauss-Newton iterations used


class IKSolver:
    """Positions-only IK for a set of named link points (bodies or sites) on one MuJoCo model."""

    def __init__(
        self,
        model: mujoco.MjModel,
        link_names: list[str] | tuple[str, ...],
        ik_joint_names: list[str] | tuple[str, ...] | None = None,
        default_qpos: np.ndarray | None = None,
        foot_link_names: list[str] | tuple[str, ...] = (),
        settings: IKSettings | None = None,
        landmarks: dict[str, tuple[str, tuple[float, float, float]]] | None = None,
        probes: ProbePoints | None = None,
    ):
        """`landmarks` {link: (frame, offset)}: the point the IK moves for that link, when it is not the link
        itself (see landmarks.py). Residuals are measured at these points; link poses at the links."""
        self.model = model
        self.data = mujoco.MjData(model)
        self.settings = settings or IKSettings()
        self.links = resolve_links(model, link_names)
        landmarks = landmarks or {}
        self.points = resolve_links(
            model,
            link_names,
            [landmarks[n][0] if n in landmarks else n for n in link_names],
            np.array([landmarks[n][1] if n in landmarks else (0.0, 0.0, 0.0) for n in link_names], dtype=np.float64),
        )
        self.default_qpos = np.array(model.qpos0 if default_qpos is None else default_qpos, dtype=np.float64)
        self.free_joint = free_joint_id(model)
        self.root_body = int(model.jnt_bodyid[self.free_joint]) if self.free_joint is not None else -1

        if ik_joint_names is None:
            joints = [j for j in range(model.njnt) if j != self.free_joint]
        else:
            joints = [int(j) for j in joint_ids(model, ik_joint_names)]
        dofs: list[int] = []
        if self.free_joint is not None:
            dofs.extend(range(model.jnt_dofadr[self.free_joint], model.jnt_dofadr[self.free_joint] + 6))
        lim_col, lim_qadr, lim_lo, lim_hi, lim_names = [], [], [], [], []
        post_col, post_qadr = [], []
        for j in joints:
            jtype = mujoco.mjtJoint(model.jnt_type[j])
            if jtype == mujoco.mjtJoint.mjJNT_FREE:
                continue
            col = len(dofs)
            dofs.extend(range(model.jnt_dofadr[j], model.jnt_dofadr[j] + _DOFS_PER_JOINT[jtype]))
            if jtype in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                post_col.append(col)
                post_qadr.append(model.jnt_qposadr[j])
                if model.jnt_limited[j]:
                    lim_col.append(col)
                    lim_qadr.append(model.jnt_qposadr[j])
                    lim_lo.append(model.jnt_range[j, 0])
                    lim_hi.append(model.jnt_range[j, 1])
                    lim_names.append(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j))
        self.dofs = np.asarray(dofs, dtype=np.int64)
        self._lim_col = np.asarray(lim_col, dtype=np.int64)
        self._lim_qadr = np.asarray(lim_qadr, dtype=np.int64)
        self._lim_lo = np.asarray(lim_lo, dtype=np.float64)
        self._lim_hi = np.asarray(lim_hi, dtype=np.float64)
        self.limited_joint_names = tuple(lim_names)
        self._post_col = np.asarray(post_col, dtype=np.int64)
        self._post_qadr = np.asarray(post_qadr, dtype=np.int64)

        # qpos entries the IK does not move: copied from the caller's preset each frame (e.g. finger joints).
        moved = np.zeros(model.nq, dtype=bool)
        for j in joints + ([self.free_joint] if self.free_joint is not None else []):
            width = 7 if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE else (
                4 if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL else 1)
            moved[model.jnt_qposadr[j]:model.jnt_qposadr[j] + width] = True
        self._preset_qadr = np.flatnonzero(~moved)

        foot_bodies = np.unique(self.points.body_ids[[link_names.index(n) for n in foot_link_names]]) \
            if foot_link_names else []
        self.sole_body, self.sole_local = sole_points(model, self.default_qpos, foot_bodies)
        self.foot_bodies = np.unique(self.sole_body)
        self.link_min_z = self._flat_foot_heights(foot_link_names)
        self._jac = np.zeros((len(self.points), 3, model.nv))
        self.probes = probes
        self._object: tuple[HullPlanes, np.ndarray, np.ndarray] | None = None  # this frame's hull, pos, rotation

    # -- setup helpers -------------------------------------------------------------------------------------------

    def _flat_foot_heights(self, foot_link_names) -> np.ndarray:
        """Per link: the lowest height its target may ask for (its height above the sole with the foot flat)."""
        min_z = np.full(len(self.points), -np.inf)
        if not len(self.sole_body):
            return min_z
        self.data.qpos[:] = self.default_qpos
        forward(self.model, self.data)
        pos = link_positions(self.data, self.points)
        soles = self._sole_world()
        for i, name in enumerate(self.points.names):
            if name not in foot_link_names:
                continue
            same_foot = self.sole_body == self.points.body_ids[i]
            sole_z = soles[same_foot, 2].min() if same_foot.any() else soles[:, 2].min()
            min_z[i] = self.settings.floor_height + pos[i, 2] - sole_z
        return min_z

    def _sole_world(self) -> np.ndarray:
        xmat = self.data.xmat[self.sole_body].reshape(-1, 3, 3)
        return self.data.xpos[self.sole_body] + np.einsum("nij,nj->ni", xmat, self.sole_local)

    def initial_qpos(self, targets: np.ndarray, root_quat_wxyz: np.ndarray | None = None) -> np.ndarray:
        """Default pose, floating base moved so the link centroid sits on the target centroid."""
        q = self.default_qpos.copy()
        if self.free_joint is None:
            return q
        adr = self.model.jnt_qposadr[self.free_joint]
        if root_quat_wxyz is not None:
            q[adr + 3:adr + 7] = root_quat_wxyz / np.linalg.norm(root_quat_wxyz)
        self.data.qpos[:] = q
        forward(self.model, self.data)
        q[adr:adr + 3] += targets.mean(axis=0) - link_positions(self.data, self.points).mean(axis=0)
        return q

    # -- solving ------------------------------------------------------------------------------------------------

    def solve_frame(
        self,
        qpos: np.ndarray,
        targets: np.ndarray,
        weights: np.ndarray,
        iterations: int,
        root_quat_wxyz: np.ndarray | None = None,
    ) -> tuple[np.ndarray, int]:
        """Refine `qpos` (nq,) toward `targets` (L, 3) with per-link `weights` (L,); returns (qpos, iterations)."""
        m, d, s = self.model, self.data, self.settings
        q = qpos.copy()
        targets = targets.copy()
        targets[:, 2] = np.maximum(targets[:, 2], self.link_min_z)
        row_w = np.repeat(weights, 3)
        n = len(self.dofs)
        used = 0
        n_polish = min(s.polish_iterations, iterations)
        # posture phase (ends early once converged), then the polish phase without the posture pull
        schedule = [s.posture_weight] * (iterations - n_polish) + [0.0] * n_polish
        it = 0
        while it < len(schedule):
            posture = schedule[it]
            it += 1
            used += 1
            d.qpos[:] = q
            forward(m, d)
            pos = link_positions(d, self.points)
            point_jacobians(m, d, self.points.body_ids, pos, self._jac)
            A = self._jac[:, :, self.dofs].reshape(-1, n)
            b = (targets - pos).reshape(-1)
            H = A.T @ (A * row_w[:, None])
            g = A.T @ (b * row_w)
            self._add_floor_rows(H, g)
            self._add_foot_roll_rows(H, g)
            self._add_object_rows(H, g)
            self._add_hand_floor_rows(H, g)
            if root_quat_wxyz is not None and s.root_rot_weight > 0 and self.root_body >= 0:
                self._add_root_rows(H, g, root_quat_wxyz)
            H[np.diag_indices(n)] += s.damping
            H[self._post_col, self._post_col] += posture
            g[self._post_col] += posture * (self.default_qpos[self._post_qadr] - q[self._post_qadr])
            dq = self._solve_with_limits(H, g, q)
            biggest = np.abs(dq).max()
            if biggest > s.max_step:
                dq *= s.max_step / biggest
            full = np.zeros(m.nv)
            full[self.dofs] = dq
            mujoco.mj_integratePos(m, q, full, 1.0)
            q[self._lim_qadr] = np.clip(q[self._lim_qadr], self._lim_lo, self._lim_hi)
            if biggest < s.step_tolerance:
                if posture == 0.0:
                    break
                it = max(it, len(schedule) - n_polish)
        self._lift_out_of_floor(q)
        return q, used

    def _add_floor_rows(self, H: np.ndarray, g: np.ndarray) -> None:
        if not len(self.sole_body):
            return
        soles = self._sole_world()
        below = np.flatnonzero(soles[:, 2] < self.settings.floor_height)
        if not len(below):
            return
        jac = np.zeros((len(below), 3, self.model.nv))
        point_jacobians(self.model, self.data, self.sole_body[below], soles[below], jac)
        Jz = jac[:, 2, self.dofs]
        w = self.settings.floor_weight
        H += w * Jz.T @ Jz
        g += w * Jz.T @ (self.settings.floor_height - soles[below, 2])

    def _add_foot_roll_rows(self, H: np.ndarray, g: np.ndarray) -> None:
        """Roll each low foot toward flat: the rotation taking its z axis to world z, about its own x axis.
        Pitch is left to the ankle and toe targets (heel and toe lift when walking)."""
        s = self.settings
        if s.foot_roll_weight <= 0 or not len(self.foot_bodies):
            return
        soles = self._sole_world()
        jacr = np.zeros((3, self.model.nv))
        for body in self.foot_bodies:
            height = soles[self.sole_body == body, 2].min() - s.floor_height
            w = s.foot_roll_weight * float(np.clip(1.0 - height / s.foot_roll_height, 0.0, 1.0))
            if w <= 0:
                continue
            mat = self.data.xmat[body].reshape(3, 3)
            x_axis, z_axis = mat[:, 0], mat[:, 2]
            err = float(np.cross(z_axis, (0.0, 0.0, 1.0)) @ x_axis)
            mujoco.mj_jac(self.model, self.data, None, jacr, self.data.xpos[body], int(body))
            row = x_axis @ jacr[:, self.dofs]
            H += w * np.outer(row, row)
            g += w * row * err

    def _lift_out_of_floor(self, q: np.ndarray) -> None:
        """Raise the floating base so that no sole point is below the floor (a hard guarantee after the soft
        floor rows)."""
        if self.free_joint is None or not len(self.sole_body):
            return
        self.data.qpos[:] = q
        mujoco.mj_kinematics(self.model, self.data)
        depth = self.settings.floor_height - self._sole_world()[:, 2].min()
        if depth > 0:
            q[self.model.jnt_qposadr[self.free_joint] + 2] += depth

    def _probe_depths(self, down_to: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Hand probes vs this frame's object: (world points, depth = radius - hull distance, face normals).
        `down_to` (m): depths below -down_to need not be exact (the hull's broad phase; they stay below it)."""
        hull, pos, rot = self._object
        world = self._probe_world()
        within = None if down_to is None else float(self.probes.radius.max()) + down_to
        dist, face = hull.signed_distance((world - pos) @ rot, within)
        return world, self.probes.radius - dist, hull.normals[face] @ rot.T

    def _add_object_rows(self, H: np.ndarray, g: np.ndarray) -> None:
        if self._object is None or self.probes is None or not len(self.probes):
            return
        world, depth, normals = self._probe_depths(self.settings.object_margin)
        # hand probes resist from the margin (no chatter at the grip); arm probes only once inside, so a forearm
        # resting near the object leaves the solution as it was
        margin = np.where(self.probes.hand, self.settings.object_margin, 0.0)
        near = np.flatnonzero(depth > -margin)
        if not len(near):
            return
        jac = np.zeros((len(near), 3, self.model.nv))
        point_jacobians(self.model, self.data, self.probes.body_ids[near], world[near], jac)
        Jn = np.einsum("ni,nij->nj", normals[near], jac[:, :, self.dofs])
        w = self.settings.object_weight
        H += w * Jn.T @ Jn
        g += w * Jn.T @ np.maximum(depth[near], 0.0)

    def _probe_world(self) -> np.ndarray:
        d, pr = self.data, self.probes
        return d.xpos[pr.body_ids] + np.einsum("nij,nj->ni", d.xmat[pr.body_ids].reshape(-1, 3, 3), pr.local)

    def _hand_floor_depths(self) -> tuple[np.ndarray, np.ndarray]:
        """Hand probes vs the floor: (world points, depth = floor + radius - z; > 0 means the sphere is below it;
        -inf on the arm probes, which the floor rows leave alone)."""
        world = self._probe_world()
        depth = self.settings.floor_height + self.probes.radius - world[:, 2]
        return world, np.where(self.probes.hand, depth, -np.inf)

    def _add_hand_floor_rows(self, H: np.ndarray, g: np.ndarray) -> None:
        s = self.settings
        if s.hand_floor_clearance < 0 or self.probes is None or not len(self.probes):
            return
        world, depth = self._hand_floor_depths()
        low = np.flatnonzero(depth > -s.hand_floor_clearance)
        if not len(low):
            return
        jac = np.zeros((len(low), 3, self.model.nv))
        point_jacobians(self.model, self.data, self.probes.body_ids[low], world[low], jac)
        Jz = jac[:, 2, self.dofs]
        H += s.floor_weight * Jz.T @ Jz
        g += s.floor_weight * Jz.T @ (depth[low] + s.hand_floor_clearance)

    def _add_root_rows(self, H: np.ndarray, g: np.ndarray, quat_wxyz: np.ndarray) -> None:
        d = self.data
        err_local = np.zeros(3)
        mujoco.mju_subQuat(err_local, quat_wxyz, d.xquat[self.root_body])
        err_world = d.xmat[self.root_body].reshape(3, 3) @ err_local
        jacr = np.zeros((3, self.model.nv))
        mujoco.mj_jac(self.model, d, None, jacr, d.xpos[self.root_body], self.root_body)
        Jr = jacr[:, self.dofs]
        w = self.settings.root_rot_weight
        H += w * Jr.T @ Jr
        g += w * Jr.T @ err_world

    def _solve_with_limits(self, H: np.ndarray, g: np.ndarray, q: np.ndarray) -> np.ndarray:
        dq = np.linalg.solve(H, g)
        if not len(self._lim_col):
            return dq
        q_lim = q[self._lim_qadr]
        wanted = q_lim + dq[self._lim_col]
        over = (wanted > self._lim_hi) | (wanted < self._lim_lo)
        if not over.any():
            return dq
        held = self._lim_col[over]
        dq_held = np.clip(wanted[over], self._lim_lo[over], self._lim_hi[over]) - q_lim[over]
        free = np.ones(len(dq), dtype=bool)
        free[held] = False
        dq = np.empty_like(dq)
        dq[held] = dq_held
        dq[free] = np.linalg.solve(H[np.ix_(free, free)], g[free] - H[np.ix_(free, held)] @ dq_held)
        return dq

    def solve(
        self,
        targets: np.ndarray,
        weights: np.ndarray,
        preset_qpos: np.ndarray | None = None,
        root_quat_wxyz: np.ndarray | None = None,
        qpos_init: np.ndarray | None = None,
        object_track: tuple[HullPlanes, np.ndarray, np.ndarray] | None = None,
    ) -> IKResult:
        """Solve a whole clip frame by frame. targets (T, L, 3), weights (T, L).

        preset_qpos (T, nq): values for the qpos entries the IK does not move (fingers); coupled joints follow.
        root_quat_wxyz (T, 4): optional weak orientation target for the floating base.
        object_track (hull, pos (T, 3), quat_wxyz (T, 4)): keeps the hand probes out of the object's hull.
        """
        T = targets.shape[0]
        if targets.shape != (T, len(self.points), 3) or weights.shape != (T, len(self.points)):
            raise ValueError(
                f"targets {targets.shape} / weights {weights.shape} do not match {len(self.links)} links")
        s = self.settings
        rq = None if root_quat_wxyz is None else np.asarray(root_quat_wxyz, dtype=np.float64)
        q = self.initial_qpos(targets[0], None if rq is None else rq[0]) if qpos_init is None else qpos_init.copy()
        qpos = np.zeros((T, self.model.nq))
        iters = np.zeros(T, dtype=np.int64)
        for t in range(T):
            if preset_qpos is not None:
                q[self._preset_qadr] = preset_qpos[t, self._preset_qadr]
            apply_joint_couplings(self.model, q)
            n_it = s.first_frame_iterations if t == 0 else s.iterations
            self._object = None if object_track is None else self._object_at(object_track, t)
            q, iters[t] = self.solve_frame(q, targets[t], weights[t], n_it, None if rq is None else rq[t])
            qpos[t] = q
        self._object = None
        return self.evaluate(qpos, targets, iters, object_track)

    def refine_frames(self, qpos: np.ndarray, targets: np.ndarray, weights: np.ndarray, frames, iterations: int,
                      object_track=None) -> np.ndarray:
        """A copy of qpos (T, nq) with `frames` re-solved for `iterations` IK iterations, warm-started from their
        current pose (with the object's push-out rows when `object_track` is given)."""
        qpos = qpos.copy()
        for t in frames:
            self._object = None if object_track is None else self._object_at(object_track, int(t))
            qpos[t] = self.solve_frame(qpos[t], targets[t], weights[t], iterations)[0]
        self._object = None
        return qpos

    def nearest_face_normals(self, qpos: np.ndarray, frames, object_track, probe_sets: list[np.ndarray]) -> np.ndarray:
        """(F, S, 3): for each of `frames` and each probe set (indices into the probes, e.g. one hand's), the outward
        world normal of the object face nearest the set's probe spheres."""
        normals = np.zeros((len(frames), len(probe_sets), 3))
        for i, t in enumerate(frames):
            self.data.qpos[:] = qpos[t]
            mujoco.mj_kinematics(self.model, self.data)
            self._object = self._object_at(object_track, int(t))
            _, depth, face_normals = self._probe_depths()
            for k, probes in enumerate(probe_sets):
                normals[i, k] = face_normals[probes[np.argmax(depth[probes])]]
        self._object = None
        return normals

    @staticmethod
    def _object_at(track, t: int) -> tuple[HullPlanes, np.ndarray, np.ndarray]:
        hull, pos, quat_wxyz = track
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, np.asarray(quat_wxyz[t], dtype=np.float64))
        return hull, np.asarray(pos[t], dtype=np.float64), rot.reshape(3, 3)

    def evaluate(
        self, qpos: np.ndarray, targets: np.ndarray, iterations: np.ndarray | None = None, object_track=None
    ) -> IKResult:
        """Link positions, residuals, floor clearance and limit contacts of given poses."""
        T = qpos.shape[0]
        link_pos = np.zeros((T, len(self.links), 3))
        link_quat = np.zeros((T, len(self.links), 4))
        point_pos = np.zeros((T, len(self.points), 3))
        sole_min = np.full(T, np.inf)
        penetration = np.zeros(T)
        hand_floor = np.zeros(T)
        for t in range(T):
            self.data.qpos[:] = qpos[t]
            mujoco.mj_kinematics(self.model, self.data)
            link_pos[t] = link_positions(self.data, self.links)
            link_quat[t] = link_quats_wxyz(self.data, self.links)
            point_pos[t] = link_positions(self.data, self.points)
            if len(self.sole_body):
                sole_min[t] = self._sole_world()[:, 2].min()
            if object_track is not None and self.probes is not None and len(self.probes):
                self._object = self._object_at(object_track, t)
                penetration[t] = max(float(self._probe_depths(0.0)[1].max()), 0.0)
            if self.probes is not None and len(self.probes):
                hand_floor[t] = max(float(self._hand_floor_depths()[1].max()), 0.0)
        self._object = None
        clamped = targets.copy()
        clamped[..., 2] = np.maximum(clamped[..., 2], self.link_min_z)
        q_lim = qpos[:, self._lim_qadr]
        at_limit = (q_lim <= self._lim_lo + 1e-4) | (q_lim >= self._lim_hi - 1e-4)
        return IKResult(
            qpos=qpos,
            link_pos=link_pos,
            link_quat_wxyz=link_quat,
            point_pos=point_pos,
            residual=np.linalg.norm(point_pos - clamped, axis=-1),
            sole_min_z=sole_min,
            object_penetration=penetration,
            hand_floor_depth=hand_floor,
            at_limit=at_limit,
            limited_joint_names=self.limited_joint_names,
            iterations=np.zeros(T, dtype=np.int64) if iterations is None else iterations,
        )


def sole_points(
    model: mujoco.MjModel, qpos: np.ndarray, body_ids, band: float = 0.005
) -> tuple[np.ndarray, np.ndarray]:
    """The lowest corners of the collision geoms on the given (foot) bodies, in body coordinates.

    Uses each geom's local bounding box (works for spheres, boxes, capsules and meshes alike), evaluated in the
    pose `qpos`; keeps corners within `band` of each body's lowest one, i.e. the sole.
    """
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    out_body, out_local = [], []
    for body in body_ids:
        geoms = [g for g in range(model.ngeom)
                 if model.geom_bodyid[g] == body and (model.geom_contype[g] or model.geom_conaffinity[g])]
        local_pts = []
        for g in geoms:
            center, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            corners_geom = center + signs * half
            rot = model.geom_quat[g]
            mat = np.zeros(9)
            mujoco.mju_quat2Mat(mat, rot)
            local_pts.append(model.geom_pos[g] + corners_geom @ mat.reshape(3, 3).T)
        if not local_pts:
            continue
        local = np.concatenate(local_pts)
        world = data.xpos[body] + local @ data.xmat[body].reshape(3, 3).T
        keep = world[:, 2] <= world[:, 2].min() + band
        out_body.extend([int(body)] * int(keep.sum()))
        out_local.append(local[keep])
    if not out_body:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    return np.asarray(out_body, dtype=np.int64), np.concatenate(out_local)

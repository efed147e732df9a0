"""SkillMimic-V2's state transition field (Sec. 4.3-4.4, supp. B.4, Alg. 1 of the supplement).

A start is drawn as: with probability p_e a state of another clip stitched to this clip (stitched trajectory
graph), else a reference frame i of this clip (by adaptive trajectory sampling); with probability p_n it is moved
uniformly within its epsilon-neighbourhood (epsilon-NSI). It is then connected to the most similar reference frame

    j = argmax_j S_k(s_new, s_j),    S_k = r^b * r^o * r^rel                                   (6), (19)

through N masked frames (the env holds the reference clock at j, rewards excluded):

    N = min(-floor(log10 beta), N_max),  beta = S_k(s_new, s_j);  beta < tau: no connection    (20)

Similarity terms on this robot, as the reward's exp(-lambda * MSE) (supp. B.3, Tab. 10 weights): r^b = link
positions (lambda_pos) x joint angles (lambda_rot); r^o = object position; r^rel = link positions relative to the
object. Velocity and object-rotation terms have weight 0 in Tab. 10 and are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import torch
from torch import Tensor

from robot_hoi.student.config import SkillMimicConfig
from robot_hoi.utils.torch_rot import quat_mul


@dataclass
class KinematicTrack:
    """What the similarity compares, per state: link positions (..., L, 3), joint angles (..., A), object (..., 3)."""

    link_pos: Tensor
    joint_pos: Tensor
    object_pos: Tensor

    def __getitem__(self, idx) -> KinematicTrack:
        return KinematicTrack(self.link_pos[idx], self.joint_pos[idx], self.object_pos[idx])

    def translated(self, offset_xy: Tensor) -> KinematicTrack:
        shift = torch.cat([offset_xy, torch.zeros(*offset_xy.shape[:-1], 1)], dim=-1)
        return KinematicTrack(self.link_pos + shift[..., None, :], self.joint_pos, self.object_pos + shift)


def _mse(a: Tensor, b: Tensor, dims: int) -> Tensor:
    return (a - b).square().flatten(-dims).mean(-1)


def similarity(a: KinematicTrack, b: KinematicTrack, cfg: SkillMimicConfig) -> Tensor:
    """S_k(a, b) = r^b * r^o * r^rel (Eq. 19), broadcasting over leading dims."""
    body = cfg.lambda_pos * _mse(a.link_pos, b.link_pos, 2) + cfg.lambda_rot * _mse(a.joint_pos, b.joint_pos, 1)
    obj = cfg.lambda_obj_pos * _mse(a.object_pos, b.object_pos, 1)
    rel = cfg.lambda_rel * _mse(a.link_pos - a.object_pos[..., None, :], b.link_pos - b.object_pos[..., None, :], 2)
    return torch.exp(-(body + obj + rel))


def masked_frames(beta: Tensor, threshold: float, max_masked: int) -> tuple[Tensor, Tensor]:
    """Eq. 20: (N, valid) for similarities beta; valid = beta >= tau."""
    n = (-torch.floor(torch.log10(beta.clamp(min=1e-300)))).clamp(min=0, max=max_masked).long()
    return n, beta >= threshold


def connect(new: KinematicTrack, reference: KinematicTrack, cfg: SkillMimicConfig) -> tuple[Tensor, Tensor]:
    """Eq. 6: (index of the most similar reference state, its similarity) for each of k new states."""
    expanded = KinematicTrack(new.link_pos[:, None], new.joint_pos[:, None], new.object_pos[:, None])
    beta, j = similarity(expanded, reference[None], cfg).max(dim=1)
    return j, beta


def quat_from_rotvec(rotvec: Tensor) -> Tensor:
    angle = rotvec.norm(dim=-1, keepdim=True)
    axis = rotvec / angle.clamp(min=1e-12)
    return torch.cat([torch.cos(0.5 * angle), torch.sin(0.5 * angle) * axis], dim=-1)


@dataclass
class StateLayout:
    """Where things are in a start state (InteractionEnv.current_states layout)."""

    nq: int
    nv: int
    actuator_qpos: Tensor
    actuator_dof: Tensor
    joint_low: Tensor
    joint_high: Tensor

    @classmethod
    def of(cls, env) -> StateLayout:
        lay = env.layout
        return cls(lay.robot_nq, lay.robot_nv, torch.as_tensor(lay.actuator_qpos), torch.as_tensor(lay.actuator_dof),
                   env.ctrl_low.cpu(), env.ctrl_high.cpu())

    @property
    def object(self) -> int:
        return self.nq + self.nv


def perturb_states(states: Tensor, lay: StateLayout, cfg: SkillMimicConfig, generator: torch.Generator) -> Tensor:
    """epsilon-NSI (Sec. 4.3.1): each quantity moved uniformly within +-eps (Tab. 9). Heights only move up (a
    lower pelvis or object would start inside the floor); joint angles stay inside their limits."""
    s = states.clone()
    k = s.shape[0]

    def u(*shape: int) -> Tensor:
        return 2.0 * torch.rand(k, *shape, generator=generator) - 1.0

    def up() -> Tensor:
        return torch.rand(k, generator=generator)

    o = lay.object
    s[:, 0:2] += cfg.eps_root_pos * u(2)
    s[:, 2] += cfg.eps_root_pos * up()
    s[:, 3:7] = quat_mul(quat_from_rotvec(cfg.eps_root_rot * u(3)), s[:, 3:7])
    s[:, lay.nq:lay.nq + 3] += cfg.eps_root_vel * u(3)
    s[:, lay.nq + 3:lay.nq + 6] += cfg.eps_root_ang_vel * u(3)
    num = lay.actuator_qpos.numel()
    s[:, lay.actuator_qpos] = torch.clamp(s[:, lay.actuator_qpos] + cfg.eps_dof * u(num), lay.joint_low,
                                          lay.joint_high)
    s[:, lay.nq + lay.actuator_dof] += cfg.eps_dof_vel * u(num)
    s[:, o:o + 2] += cfg.eps_obj_pos * u(2)
    s[:, o + 2] += cfg.eps_obj_pos * up()
    s[:, o + 3:o + 7] = quat_mul(quat_from_rotvec(cfg.eps_obj_rot * u(3)), s[:, o + 3:o + 7])
    s[:, o + 7:o + 10] += cfg.eps_obj_vel * u(3)
    s[:, o + 10:o + 13] += cfg.eps_obj_ang_vel * u(3)
    return s


def translate_states(states: Tensor, offset_xy: Tensor, lay: StateLayout) -> Tensor:
    """Move robot and object horizontally (supp. B.4: align a stitched state's root with its target's)."""
    s = states.clone()
    s[:, 0:2] += offset_xy
    s[:, lay.object:lay.object + 2] += offset_xy
    return s


class LinkKinematics:
    """Link positions of arbitrary start states (forward kinematics of the scene, the env's link sensors)."""

    def __init__(self, env) -> None:
        self.model = env.scene.model
        self.data = mujoco.MjData(self.model)
        self.layout = env.layout

    def __call__(self, states: Tensor) -> Tensor:
        lay = self.layout
        out = np.zeros((states.shape[0], lay.num_links * 3))
        for i, state in enumerate(states.double().numpy()):
            self.data.qpos[: lay.robot_nq] = state[: lay.robot_nq]
            start = lay.robot_nq + lay.robot_nv
            self.data.qpos[lay.object_qpos:lay.object_qpos + 7] = state[start:start + 7]
            mujoco.mj_forward(self.model, self.data)
            out[i] = self.data.sensordata[lay.link_pos]
        return torch.as_tensor(out, dtype=torch.float32).reshape(-1, lay.num_links, 3)


class StitchedGraph:
    """Sec. 4.4: every frame of the other clips (B), aligned horizontally and connected to its most similar frame
    of clip A; connections with beta < tau are left out. edges[A] = (source frame, target frame, xy offset)."""

    def __init__(self, track: KinematicTrack, root_xy: Tensor, clip_start: Tensor, clip_end: Tensor,
                 cfg: SkillMimicConfig, max_sources: int = 1024, chunk: int = 32) -> None:
        self.edges: dict[int, tuple[Tensor, Tensor, Tensor]] = {}
        total = int(clip_end[-1]) + 1
        for a, (start, end) in enumerate(zip(clip_start.tolist(), clip_end.tolist(), strict=True)):
            targets = torch.arange(start, max(end, start + 1))
            inside = torch.zeros(total, dtype=torch.bool)
            inside[start:end + 1] = True
            sources = (~inside).nonzero().flatten()
            if sources.numel() == 0:
                continue
            sources = sources[:: max(1, sources.numel() // max_sources)]
            best_j, best_beta, best_off = [], [], []
            for part in sources.split(chunk):
                offset = root_xy[targets][None] - root_xy[part][:, None]  # (S, T, 2)
                moved = KinematicTrack(track.link_pos[part][:, None], track.joint_pos[part][:, None],
                                       track.object_pos[part][:, None]).translated(offset)
                sim = similarity(moved, track[targets][None], cfg)  # (S, T)
                beta, j = sim.max(dim=1)
                best_j.append(targets[j])
                best_beta.append(beta)
                best_off.append(offset[torch.arange(part.numel()), j])
            beta = torch.cat(best_beta)
            valid = beta >= cfg.similarity_threshold
            if valid.any():
                self.edges[a] = (sources[valid], torch.cat(best_j)[valid], torch.cat(best_off)[valid])

    def num_edges(self, clip: int) -> int:
        return 0 if clip not in self.edges else int(self.edges[clip][0].numel())


@dataclass
class StfStarts:
    state: Tensor  # (k, S)
    frame: Tensor  # (k,) reference frame j the start connects to
    hold: Tensor  # (k,) masked frames N
    centroid: Tensor  # (k,) ATS start frame i (-1: a stitched external state)


class StateTransitionField:
    def __init__(self, env, cfg: SkillMimicConfig, generator: torch.Generator, ats=None,
                 graph: StitchedGraph | None = None) -> None:
        self.cfg, self.generator, self.ats, self.graph = cfg, generator, ats, graph
        self.layout = StateLayout.of(env)
        self.kinematics = LinkKinematics(env)
        self.clip_start, self.clip_end = env.clip_start.long().cpu(), env.clip_end.long().cpu()
        self.states = reference_states(env)
        self.track = reference_track(env)

    def starts(self, clip: int) -> Tensor:
        start, end = int(self.clip_start[clip]), int(self.clip_end[clip])
        return torch.arange(start, max(end, start + 1))

    def sample(self, clips: Tensor) -> StfStarts:
        cfg, gen = self.cfg, self.generator
        k = clips.numel()
        base = torch.zeros(k, dtype=torch.long)  # reference frame each start was drawn around
        centroid = torch.full((k,), -1, dtype=torch.long)
        state = torch.zeros(k, self.states.shape[1])
        track = KinematicTrack(torch.zeros(k, *self.track.link_pos.shape[1:]),
                               torch.zeros(k, self.track.joint_pos.shape[1]), torch.zeros(k, 3))
        external = torch.rand(k, generator=gen) < cfg.external_probability
        for clip in clips.unique().tolist():
            rows = (clips == clip).nonzero().flatten()
            ext = rows[external[rows]] if self.graph is not None and self.graph.num_edges(clip) else rows[:0]
            own = rows[~torch.isin(rows, ext)]
            if ext.numel():
                src, dst, off = self.graph.edges[clip]
                pick = torch.randint(src.numel(), (ext.numel(),), generator=gen)
                state[ext] = translate_states(self.states[src[pick]], off[pick], self.layout)
                moved = self.track[src[pick]].translated(off[pick])
                track.link_pos[ext], track.joint_pos[ext], track.object_pos[ext] = \
                    moved.link_pos, moved.joint_pos, moved.object_pos
                base[ext] = dst[pick]
            if own.numel():
                if self.ats is not None:
                    frames = self.ats.sample_frames(torch.full((own.numel(),), clip), gen)
                else:
                    candidates = self.starts(clip)
                    frames = candidates[torch.randint(candidates.numel(), (own.numel(),), generator=gen)]
                state[own] = self.states[frames]
                track.link_pos[own], track.joint_pos[own], track.object_pos[own] = \
                    self.track.link_pos[frames], self.track.joint_pos[frames], self.track.object_pos[frames]
                base[own], centroid[own] = frames, frames
        if not cfg.stf:  # reference starts chosen by ATS, no neighbourhood and no connection
            return StfStarts(state, base, torch.zeros(k, dtype=torch.long), centroid)
        moved_rows = (torch.rand(k, generator=gen) < cfg.neighbourhood_probability).nonzero().flatten()
        if moved_rows.numel():
            state[moved_rows] = perturb_states(state[moved_rows], self.layout, cfg, gen)
            track.link_pos[moved_rows] = self.kinematics(state[moved_rows])
            track.joint_pos[moved_rows] = state[moved_rows][:, self.layout.actuator_qpos]
            obj = self.layout.object
            track.object_pos[moved_rows] = state[moved_rows, obj:obj + 3]
        frame = base.clone()
        hold = torch.zeros(k, dtype=torch.long)
        for clip in clips.unique().tolist():
            rows = (clips == clip).nonzero().flatten()
            candidates = self.starts(clip)
            j, beta = connect(track[rows], self.track[candidates], cfg)
            n, valid = masked_frames(beta, cfg.similarity_threshold, cfg.max_masked)
            frame[rows] = torch.where(valid, candidates[j], base[rows])
            hold[rows] = torch.where(valid, n, 0)
            bad = rows[~valid]  # no connection: start from the reference frame itself
            state[bad] = self.states[base[bad]]
        return StfStarts(state, frame, hold, centroid)


def reference_states(env) -> Tensor:
    """Every reference frame as a start state (current_states layout, object angular velocity in world axes), on
    the host like every table of the start samplers."""
    return torch.cat([env.ref_robot_qpos, env.ref_robot_qvel, env.ref_object_pos, env.ref_object_quat,
                      env.ref_object_lin_vel, env.ref_object_ang_vel], dim=1).cpu()


def reference_track(env) -> KinematicTrack:
    return KinematicTrack(env.ref_link_pos.cpu(), env.ref_joint_pos.cpu(), env.ref_object_pos.cpu())

"""Interaction-imitation environment: the G1+Inspire tracks a robot-space HOI reference with the clip's object.

step(): actions -> PD targets -> physics (decimation sub-steps in the backend) -> state -> reference clock
-> rewards -> terminations -> PSI bookkeeping -> resets -> observations. Terms live in mdp/; this class only
composes them. All tensors are batched over environments; no per-environment Python on the step path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from types import SimpleNamespace

import torch
from torch import Tensor

from deploy.contract import warmup_offset
from deploy.safety import rate_limited
from robot_hoi import termination
from robot_hoi.errors import UserError
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
from robot_hoi.tasks.interaction.mdp import assist as assist_terms
from robot_hoi.tasks.interaction.mdp import observations as obs_terms
from robot_hoi.tasks.interaction.mdp import randomization as dr
from robot_hoi.tasks.interaction.mdp import rewards as reward_terms
from robot_hoi.tasks.interaction.mdp import terminations as term_terms
from robot_hoi.tasks.interaction.psi import PsiBuffer
from robot_hoi.tasks.interaction.reference import (
    ReferenceMotion,
    nearest_surface_vectors,
    object_points_world,
)
from robot_hoi.tasks.interaction.scene_setup import InteractionScene
from robot_hoi.utils.timing import OFF
from robot_hoi.utils.torch_rot import (
    quat_apply,
    quat_apply_inverse,
    quat_from_yaw,
    quat_mul,
    quat_to_matrix,
    yaw_quat,
)


@dataclass
class ReferenceFrame:
    link_pos: Tensor
    link_quat_wxyz: Tensor
    d_hat: Tensor
    object_pos: Tensor
    object_quat_wxyz: Tensor
    hand_contact: Tensor
    hand_distance: Tensor
    root_pos: Tensor
    root_quat_wxyz: Tensor
    joint_pos: Tensor    # PD targets of a zero action: the state's joints plus the grasp squeeze and load offsets
    joint_state: Tensor  # the reference state's actuated joints (what a robot on the reference measures)
    joint_vel: Tensor    # the reference state's actuated joint velocities
    link_vel: Tensor     # (L, 3) world linear velocities of the mapped links (finite differences of link_pos)
    link_rotmat: Tensor
    object_rotmat: Tensor
    root_rotmat: Tensor


@dataclass
class StartPlan:
    """What an optional `env.start_sampler.plan(env, env_ids)` decides for the envs being reset (n rows): the clip
    of every row, and for the `custom` rows the full start: robot + object state (current_states() layout, object
    angular velocity in world axes), reference frame and frames the reference clock is held (like the warm-up).
    The other rows start as usual (stand or reference/PSI) on the given clip."""

    clip: Tensor                 # (n,) long
    custom: Tensor               # (n,) bool
    state: Tensor | None = None  # (n, robot_nq + robot_nv + 13), read where custom
    frame: Tensor | None = None  # (n,) long absolute reference frame, read where custom
    hold: Tensor | None = None   # (n,) long, read where custom


class InteractionEnv:
    """Implements robot_hoi.rl.env.VecEnv."""

    def __init__(self, cfg: InteractionEnvCfg, scene: InteractionScene, references: list[ReferenceMotion]):
        if cfg.action_offset not in ("reference", "default"):
            raise UserError(f"env.action_offset must be 'reference' or 'default', not {cfg.action_offset!r}")
        self.cfg = cfg
        self.scene = scene
        self.num_envs = cfg.num_envs
        dr.check(cfg.randomization)
        obs_terms.check_student_terms(cfg.student_obs_terms)
        self.backend = scene.make_backend(cfg.num_envs, backend=cfg.backend, nthread=cfg.nthread,
                                          device=cfg.sim_device, variable_fields=dr.variable_fields(cfg.randomization))
        self.device = self.backend.device  # every env tensor lives where the physics state is
        self.dt = self.backend.control_dt
        self.generator = torch.Generator(device=self.device).manual_seed(cfg.seed)
        self.start_sampler = None  # optional: chooses reset clips/states (StartPlan); e.g. the student's samplers
        self.timers = OFF  # a robot_hoi.utils.timing.Timers splits step() into stages (bench/train_throughput.py)
        layout = scene.layout
        self.layout = layout
        self.num_actions = len(layout.actuator_names)
        emb = scene.embodiment
        as_tensor = lambda a: torch.tensor(a, dtype=torch.float32, device=self.device)  # noqa: E731
        self.default_joint_pos = as_tensor(emb.default_pos)
        self.action_scale = as_tensor(emb.action_scale)
        lo, hi = scene.actuator_ctrlrange()
        self.ctrl_low, self.ctrl_high = as_tensor(lo), as_tensor(hi)
        self._default_robot_qpos = scene.default_robot_qpos().to(self.device)
        hand_joints = {c.joint for hand in emb.hands.values() for c in hand.channels}
        self.body_actuator_ids = [i for i, n in enumerate(layout.actuator_names) if n not in hand_joints]
        contact_index = {n: i for i, n in enumerate(layout.contact_names)}
        self.hand_force_sensor_ids = [contact_index[f"{prefix}{finger}"] for prefix in ("L_", "R_")
                                      for finger in obs_terms.FINGER_CHANNEL_SENSORS]
        self._setup_references(references)
        self.reward_weights = {n: t.weight for n, t in cfg.rewards.items() if t is not None}
        self.reward_funcs = {n: (reward_terms.REWARD_TERMS[t.func], t.params)
                             for n, t in cfg.rewards.items() if t is not None}
        self.reward_scales = {n: t.scale for n, t in cfg.rewards.items() if t is not None}
        self.reward_penalties = frozenset(n for n, t in cfg.rewards.items() if t is not None and t.kind == "penalty")
        if cfg.reward_mode not in ("product", "sum"):
            raise UserError(f"env.reward_mode must be 'product' or 'sum', not {cfg.reward_mode!r}")
        for name, term in cfg.rewards.items():
            if term is not None and term.kind not in ("exp", "penalty"):
                raise UserError(f"env.rewards.{name}.kind must be 'exp' or 'penalty', not {term.kind!r}")
        self.object_mass = torch.full((cfg.num_envs,), scene.object_mass, device=self.device)  # kg, per env
        self.object_mass_levels = object_mass_levels(scene.object_mass, cfg.randomization.object_mass_scale)
        if self.object_mass_levels is not None:
            self.backend.set_body_mass_levels(scene.object_body_id(), self.object_mass_levels.tolist())
            self.object_mass_levels = self.object_mass_levels.to(self.device)
        self.randomization = dr.DomainRandomization(cfg.randomization, self, obs_terms.STUDENT_NOISE)
        self.assist_level = assist_terms.assist_level(cfg.assist, 0)
        self.feet_link_mask = torch.zeros(layout.num_links, device=self.device)
        self.feet_link_mask[scene.feet_link_ids] = 1.0
        # an episode from the stand must be able to cover the longest clip plus its warmup
        longest = int((self.clip_end - self.clip_start).max()) + 1
        self.max_episode_length = max(cfg.max_episode_frames, longest + cfg.warmup_frames + 1)
        self._rsi_noise_qpos = torch.as_tensor(
            [q for q, name in zip(layout.actuator_qpos, layout.actuator_names, strict=True) if name not in hand_joints],
            device=self.device)
        self.psi = PsiBuffer(cfg.psi, state_dim=layout.robot_nq + layout.robot_nv + 13, generator=self.generator)
        if cfg.psi.enabled:  # the buffer starts with the reference-derived states (RSI), supp. E.2 (i)
            lo, hi = cfg.init.start_range
            frames = torch.cat([torch.arange(int(s + lo * (e - s)), max(int(s + hi * (e - s)), int(s + lo * (e - s)) + 1),
                                             device=self.device)
                                for s, e in zip(self.clip_start.tolist(), self.clip_end.tolist(), strict=True)])
            self.psi.seed_from_reference(frames)
        self._allocate()
        self.reset()
        self.obs_dims = {name: value.shape[1] for name, value in self._observations().items()}

    # ---- setup --------------------------------------------------------------------------------------------------
    def _setup_references(self, references: list[ReferenceMotion]) -> None:
        if not references:
            raise ValueError("the environment needs at least one reference motion")
        cat = lambda name: torch.cat([getattr(r, name) for r in references]).to(self.device)  # noqa: E731
        self.reference = references[0] if len(references) == 1 else None
        self.references = references
        self.ref_link_pos, self.ref_link_quat = cat("link_pos"), cat("link_quat_wxyz")
        self.ref_d_hat, self.ref_hand_contact = cat("d_hat"), cat("hand_contact")
        self.ref_object_pos, self.ref_object_quat = cat("object_pos"), cat("object_quat_wxyz")
        # the clip's own object path, where a planned grasp moved the reference's (None: the same path); evaluation
        # reports E_o against both
        moved = [r.source_object_pos is not None and not (torch.equal(r.source_object_pos, r.object_pos) and
                 torch.equal(r.source_object_quat_wxyz, r.object_quat_wxyz)) for r in references]
        self.source_object_pos = self.source_object_rotmat = None
        if any(moved):
            own = lambda name: torch.cat([getattr(r, f"source_{name}") if m else getattr(r, name)  # noqa: E731
                                          for r, m in zip(references, moved, strict=True)]).to(self.device)
            self.source_object_pos = own("object_pos")
            self.source_object_rotmat = quat_to_matrix(own("object_quat_wxyz"))
        self.ref_object_lin_vel, self.ref_object_ang_vel = cat("object_lin_vel"), cat("object_ang_vel")
        self.ref_robot_qpos, self.ref_robot_qvel = cat("robot_qpos"), cat("robot_qvel")
        self.ref_joint_pos = cat("joint_pos")
        self.ref_joint_state = self.ref_robot_qpos[:, torch.as_tensor(self.layout.actuator_qpos, device=self.device)]
        self.ref_joint_vel = self.ref_robot_qvel[:, torch.as_tensor(self.layout.actuator_dof, device=self.device)]
        self.ref_link_vel = torch.cat([link_velocities(r) for r in references]).to(self.device)
        # rotation matrices of the whole reference, computed once (the observation terms use matrices)
        self.ref_link_rotmat = quat_to_matrix(self.ref_link_quat)
        self.ref_object_rotmat = quat_to_matrix(self.ref_object_quat)
        self.ref_root_rotmat = quat_to_matrix(self.ref_robot_qpos[:, 3:7])
        lengths = torch.tensor([r.num_frames for r in references], device=self.device)
        self.clip_start = torch.cumsum(lengths, 0) - lengths
        self.clip_end = self.clip_start + lengths - 1
        self.object_points = _subsample(references[0].object_points, self.cfg.object_surface_points).to(self.device)
        # d_hat from the same surface samples the simulation's d uses (else |d_hat - d| > 0 on the reference itself)
        ref_points_world = object_points_world(self.object_points, self.ref_object_pos, self.ref_object_rotmat)
        self.ref_d_hat = nearest_surface_vectors(self.ref_link_pos, ref_points_world)
        wrists = [self.layout.link_names.index(n) for n in ("left_wrist_yaw_link", "right_wrist_yaw_link")]
        self.ref_hand_distance = self.ref_d_hat[:, wrists].norm(dim=-1)
        self.total_frames = int(lengths.sum())

    def _allocate(self) -> None:
        n, a = self.num_envs, self.num_actions
        z = lambda *s, dtype=torch.float32: torch.zeros(*s, dtype=dtype, device=self.device)  # noqa: E731
        self.actions, self.last_actions = z(n, a), z(n, a)
        self.last_ctrl = z(n, a)  # the PD targets last commanded (where command_rate_limit moves them from)
        self.clip_id = z(n, dtype=torch.long)
        self.ref_index = z(n, dtype=torch.long)
        self.warmup_left = z(n, dtype=torch.long)
        self.warmup_length = z(n, dtype=torch.long)  # the warmup each episode began with
        self.warmup_start_pos = z(n, self.num_actions)  # actuated joints when it began (the warmup blend's start)
        self.episode_length = z(n, dtype=torch.long)
        self.tracked_steps = z(n, dtype=torch.long)   # steps after the warmup: what duration and errors cover
        self.start_frame = z(n, dtype=torch.long)
        self.contact_loss_frames = z(n, 2, dtype=torch.long)
        self.prev_link_vel = z(n, self.layout.num_links, 3)
        self.prev_object_vel = z(n, 3)
        self.episode_sums: dict[str, Tensor] = {name: z(n) for name in self.reward_weights}
        self.episode_error_h, self.episode_error_o, self.episode_error_o_source = z(n), z(n), z(n)
        self.episode_max_error_h, self.episode_max_error_o = z(n), z(n)
        self.failure_counts = z(len(self.references), self.cfg.init.failure_segments)
        self.assisted = z(n)  # 1 where this episode gets the assist wrenches (drawn per episode)
        self.grip_settle_left = z(n, dtype=torch.long)  # frames of a reference start's grip settle left

    # ---- VecEnv -------------------------------------------------------------------------------------------------
    def reset(self) -> dict[str, Tensor]:
        self._reset_envs(torch.arange(self.num_envs, device=self.device))
        return self._observations()

    def step(self, actions: Tensor):
        timers = self.timers
        timers.start()
        self.actions = actions.detach().clamp(-self.cfg.action_clip, self.cfg.action_clip)
        targets = self.action_offset() + self.action_scale * self.actions
        wrench = assist_terms.assist_wrench(self, self.assist_level) if self.assist_level > 0 else None
        if self.cfg.init.grip_settle_frames > 0:
            settle = assist_terms.grip_settle_wrench(self)
            wrench = settle if wrench is None else wrench + settle
        ctrl = torch.maximum(torch.minimum(targets, self.ctrl_high), self.ctrl_low)
        if self.cfg.command_rate_limit is not None:
            ctrl = rate_limited(ctrl, self.last_ctrl, self.cfg.command_rate_limit * self.dt)
        self.last_ctrl = ctrl.clone()  # the delay line may hold `ctrl`; resets write into last_ctrl
        ctrl = self.randomization.delayed(ctrl)
        self.randomization.push(self.dt)
        self.backend.step(ctrl, wrench)
        timers.lap("physics")
        self.grip_settle_left = (self.grip_settle_left - 1).clamp(min=0)
        self.episode_length += 1
        in_warmup = self.warmup_left > 0
        self.warmup_left = (self.warmup_left - 1).clamp(min=0)
        self.ref_index = torch.where(in_warmup, self.ref_index, torch.minimum(self.ref_index + 1, self._clip_end()))
        self.tracked_steps += (~in_warmup).long()
        self._update_state()
        self._update_history()

        costs = {name: func(self, **params) for name, (func, params) in self.reward_funcs.items()}
        reward, per_term = reward_terms.aggregate(costs, self.reward_weights, self.cfg.reward_mode, self.reward_scales,
                                                   self.reward_penalties)
        for name, value in per_term.items():
            self.episode_sums[name] += value
        self._accumulate_metrics(~in_warmup)

        reasons = self._terminations()
        terminated = torch.stack(list(reasons.values())).any(0)
        if self.cfg.init.failure_weighted:
            self._count_failures(terminated)
        reached_end = self.ref_index >= self._clip_end()
        truncated = ~terminated & (reached_end | (self.episode_length >= self.max_episode_length))
        self.psi.observe(self, reward, terminated | truncated)
        done = terminated | truncated
        stats = self._episode_stats(done, terminated, reached_end)
        stats.update({f"ended_by/{k}": v[done].float() for k, v in reasons.items()})  # what ended each episode
        extras = {"log": self._episode_log(done, stats), "episode": stats}
        if terminated.any():
            extras["log"].update({f"Termination/{k}": v[terminated].float().mean() for k, v in reasons.items()})
        timers.lap("state_rewards_terminations")
        if truncated.any():
            extras["final_obs"] = self._observations()
        self.last_actions = self.actions.clone()
        timers.lap("observations")
        done_ids = done.nonzero().flatten()
        if done_ids.numel():
            self._reset_envs(done_ids)
        timers.lap("resets")
        obs = self._observations()
        timers.lap("observations")
        return obs, reward, terminated, truncated, extras

    def close(self) -> None:
        """Stop the backend's physics threads now (the env is not stepped after)."""
        close = getattr(self.backend, "close", None)
        if close is not None:
            close()

    # ---- curriculum ---------------------------------------------------------------------------------------------
    def update_curriculum(self, total_samples: int) -> dict[str, float]:
        """Called by the runner before each iteration; returns what to log."""
        self.assist_level = assist_terms.assist_level(self.cfg.assist, total_samples)
        thresholds = assist_terms.terminations_at(self.cfg.assist, self.cfg.terminations, self.assist_level)
        return {"Curriculum/assist_level": self.assist_level,
                "Curriculum/object_termination_m": thresholds.max_mean_object_point_error}

    def curriculum_state(self) -> dict[str, float]:
        """Saved with each checkpoint: the curriculum level reached."""
        return {"assist_level": self.assist_level}

    def action_offset(self) -> Tensor:
        """PD target for a zero action: the default pose, or (action_offset "reference") the reference joint
        positions of the frame this step moves to, so that the policy learns corrections to the retarget."""
        if self.cfg.action_offset == "default":
            return self.default_joint_pos
        frame, steps_done = self.offset_frame()
        return self.zero_action_target(self.ref_joint_pos[frame], steps_done)

    def offset_frame(self, previous: bool = False) -> tuple[Tensor, Tensor]:
        """(reference frame, warmup steps done) behind this step's zero-action target; `previous`: behind the
        step just taken (it moved the env to the frame it stands at now; 0 steps after a reset: frame only)."""
        if previous:
            return self.ref_index, self.episode_length - 1
        in_warmup = self.warmup_left > 0
        frame = torch.where(in_warmup, self.ref_index, torch.minimum(self.ref_index + 1, self._clip_end()))
        return frame, self.warmup_length - self.warmup_left

    def zero_action_target(self, frame_joints: Tensor, steps_done: Tensor) -> Tensor:
        """The "reference" zero-action target around `frame_joints` (num_envs, J), `steps_done` steps into the
        episode: inside the warmup it glides from the start pose (warmup_blend). ReferenceView calls it with a
        teacher's own reference joints."""
        if not self.cfg.warmup_blend:
            return frame_joints
        in_warmup = steps_done < self.warmup_length
        blended = warmup_offset(self.warmup_start_pos, frame_joints, steps_done[:, None].float(),
                                self.warmup_length[:, None].clamp(min=1))
        return torch.where(in_warmup[:, None], blended, frame_joints)

    # ---- state --------------------------------------------------------------------------------------------------
    def _clip_end(self) -> Tensor:
        return self.clip_end[self.clip_id]

    def _update_state(self, env_ids: Tensor | None = None) -> None:
        """The state the terms read, from the backend's qpos, qvel and sensors (each read once). `env_ids`: only
        these rows are recomputed (after their reset); the other rows keep their values, which are what a full
        update would give again (their physics state and reference index did not change). Rows are computed
        independently of each other, so the result is the same bit for bit (tests/tasks/test_state_update.py)."""
        if env_ids is None:
            self._compute_state(self, None)
            return
        rows = SimpleNamespace()
        self._compute_state(rows, env_ids)
        for name, value in vars(rows).items():  # new tensors: a kept reference to the old ones stays unchanged
            old = getattr(self, name)
            if isinstance(value, ReferenceFrame):
                value = ReferenceFrame(**{f.name: getattr(old, f.name).index_copy(0, env_ids, getattr(value, f.name))
                                          for f in fields(ReferenceFrame)})
            else:
                value = old.index_copy(0, env_ids, value)
            setattr(self, name, value)

    def _compute_state(self, s, env_ids: Tensor | None) -> None:
        """Set the state attributes on `s` (the env itself, or a namespace for the rows `env_ids`)."""
        lay = self.layout
        qpos = self.backend.qpos.to(torch.float32)
        qvel = self.backend.qvel.to(torch.float32)
        sens = self.backend.sensordata.to(torch.float32)
        ref_index = self.ref_index
        if env_ids is not None:
            qpos, qvel, sens, ref_index = qpos[env_ids], qvel[env_ids], sens[env_ids], ref_index[env_ids]
        n, nl = qpos.shape[0], lay.num_links
        s.root_pos, s.root_quat = qpos[:, 0:3], qpos[:, 3:7]
        s.root_lin_vel, s.root_ang_vel = qvel[:, 0:3], qvel[:, 3:6]
        s.joint_pos = qpos[:, lay.actuator_qpos]
        s.joint_vel = qvel[:, lay.actuator_dof]
        s.object_pos = qpos[:, lay.object_qpos:lay.object_qpos + 3]
        s.object_quat = qpos[:, lay.object_qpos + 3:lay.object_qpos + 7]
        s.object_lin_vel = qvel[:, lay.object_dof:lay.object_dof + 3]
        # free-joint angular velocity is in the body frame; the observation wants it in world axes
        s.object_rotmat = quat_to_matrix(s.object_quat)
        s.object_ang_vel = (s.object_rotmat @ qvel[:, lay.object_dof + 3:lay.object_dof + 6, None])[..., 0]
        s.link_pos = sens[:, lay.link_pos].reshape(n, nl, 3)
        s.link_quat = sens[:, lay.link_quat].reshape(n, nl, 4)
        s.link_rotmat = quat_to_matrix(s.link_quat)
        s.root_rotmat = quat_to_matrix(s.root_quat)
        s.heading_matrix = quat_to_matrix(yaw_quat(s.root_quat))
        s.link_vel = sens[:, lay.link_vel].reshape(n, nl, 3)
        contact = sens[:, lay.contact].reshape(n, -1, 4)
        s.contact_found = contact[..., 0] > 0
        s.contact_force = contact[..., 1:]
        s.hand_contact_found = s.contact_found[:, self.scene.hand_contact_ids]
        s.finger_contact_found = s.contact_found[:, self.scene.finger_contact_ids]

        s.object_points_world = object_points_world(self.object_points, s.object_pos, s.object_rotmat)
        s.d = nearest_surface_vectors(s.link_pos, s.object_points_world)
        s.ref = reference_frame(self, ref_index)
        s.ref_heading_matrix = quat_to_matrix(yaw_quat(s.ref.root_quat_wxyz))
        s.ref_object_points_world = object_points_world(self.object_points, s.ref.object_pos, s.ref.object_rotmat)
        s.w_d = termination.interaction_weights(s.d, s.ref.d_hat)

    def _update_history(self) -> None:
        """What accumulates over steps, once per env step (never on resets): finite-difference accelerations
        and the frames a required hand contact has been missing."""
        self.link_acc = (self.link_vel - self.prev_link_vel) / self.dt
        self.object_acc = (self.object_lin_vel - self.prev_object_vel) / self.dt
        self.prev_link_vel, self.prev_object_vel = self.link_vel.clone(), self.object_lin_vel.clone()
        need = self.ref.hand_contact & (self.warmup_left == 0)[:, None]
        distance, ref_distance = self.d.norm(dim=-1), self.ref.d_hat.norm(dim=-1)
        near = torch.stack([distance[:, ids].amin(-1) for ids in self.scene.hand_link_ids], dim=-1)
        ref_near = torch.stack([ref_distance[:, ids].amin(-1) for ids in self.scene.hand_link_ids], dim=-1)
        self.contact_loss_frames = termination.contact_loss_count(
            self.contact_loss_frames, need, self.hand_contact_found, near, self.cfg.terminations, ref_near)

    def reference_at(self, k: int) -> ReferenceFrame:
        idx = torch.minimum(self.ref_index + k, self._clip_end()) if k else self.ref_index
        return reference_frame(self, idx)

    def set_terminations(self, thresholds: termination.Thresholds) -> None:
        """End episodes by these thresholds from the next step on (evaluation scores one rollout protocol under
        several success definitions)."""
        self.cfg.terminations = thresholds

    def _terminations(self) -> dict[str, Tensor]:
        thresholds = assist_terms.terminations_at(self.cfg.assist, self.cfg.terminations, self.assist_level)
        return term_terms.interaction_terminations(self, thresholds)

    # ---- metrics ------------------------------------------------------------------------------------------------
    def _accumulate_metrics(self, tracking: Tensor) -> None:
        """E_h and E_o summed over the steps after the warmup (the imitated duration)."""
        body = self.scene.body_link_ids  # E_h excludes hand joints for OMOMO (InterMimic Sec. 4)
        error_h = (self.ref.link_pos[:, body] - self.link_pos[:, body]).norm(dim=-1).mean(-1)
        error_o = (self.object_points_world - self.ref_object_points_world).norm(dim=-1).mean(-1)
        error_source = error_o
        if self.source_object_pos is not None:  # only a grasp-moved reference costs the second error
            source_points = object_points_world(self.object_points, self.source_object_pos[self.ref_index],
                                                self.source_object_rotmat[self.ref_index])
            error_source = (self.object_points_world - source_points).norm(dim=-1).mean(-1)
        self.episode_error_h += torch.where(tracking, error_h, 0.0)
        self.episode_error_o += torch.where(tracking, error_o, 0.0)
        self.episode_error_o_source += torch.where(tracking, error_source, 0.0)
        self.episode_max_error_h = torch.maximum(self.episode_max_error_h, torch.where(tracking, error_h, 0.0))
        self.episode_max_error_o = torch.maximum(self.episode_max_error_o, torch.where(tracking, error_o, 0.0))

    def _episode_stats(self, done: Tensor, terminated: Tensor, reached_end: Tensor) -> dict[str, Tensor]:
        """Per finished episode: InterMimic's success, duration (s, after the warmup), E_h and E_o (cm, averaged
        over that duration). Success: the clip's end reached without termination, after tracking at least
        `success_min_frames_fraction` of the clip (an episode started near the end is not a success)."""
        steps = self.tracked_steps[done].clamp(min=1).float()
        clip = self.clip_id[done]
        clip_frames = (self.clip_end[clip] - self.clip_start[clip]).float()
        covered = (self.ref_index[done] - self.start_frame[done]).float() >= \
            self.cfg.success_min_frames_fraction * clip_frames
        success = reached_end[done] & ~terminated[done] & covered
        tracked = termination.interaction_tracked(self.episode_max_error_o[done], self.episode_max_error_h[done],
                                                  self.cfg.success_max_object_error, self.cfg.success_max_link_error)
        return {
            "success": success.float(),
            "interaction_success": (success & tracked).float(),
            "E_h_max_cm": 100 * self.episode_max_error_h[done],
            "E_o_max_cm": 100 * self.episode_max_error_o[done],
            "duration_s": steps * self.dt,
            "E_h_cm": 100 * self.episode_error_h[done] / steps,
            "E_o_cm": 100 * self.episode_error_o[done] / steps,
            "E_o_source_cm": 100 * self.episode_error_o_source[done] / steps,
            "clip_id": self.clip_id[done].float(),
        }

    def _episode_log(self, done: Tensor, stats: dict[str, Tensor]) -> dict[str, Tensor | float]:
        """Means over the episodes that ended this step as 0-d device tensors (the runner reads them back once
        per iteration)."""
        if not done.any():
            return {}
        steps = self.episode_length[done].clamp(min=1).float()
        log = {f"Episode_Reward/{name}": (s[done] / steps).mean() for name, s in self.episode_sums.items()}
        log["Metrics/episode_length"] = steps.mean()
        for key in ("success", "interaction_success", "duration_s", "E_h_cm", "E_o_cm"):
            log[f"Metrics/{key}"] = stats[key].mean()
        log["Metrics/psi_buffer"] = float(len(self.psi))
        return log

    # ---- resets -------------------------------------------------------------------------------------------------
    def _reset_envs(self, env_ids: Tensor) -> None:
        n = env_ids.numel()
        init = self.cfg.init
        plan = self.start_sampler.plan(self, env_ids) if self.start_sampler is not None else None
        clip = plan.clip.clone() if plan is not None else \
            torch.randint(len(self.references), (n,), generator=self.generator, device=self.device)
        custom = plan.custom if plan is not None else torch.zeros(n, dtype=torch.bool, device=self.device)
        stand = (torch.rand(n, generator=self.generator, device=self.device) < init.stand_start_probability) & ~custom
        frame = self.clip_start[clip].clone()
        robot_state = torch.zeros(n, self.layout.robot_nq + self.layout.robot_nv, device=self.device)
        object_state = torch.zeros(n, 13, device=self.device)
        custom_ids = custom.nonzero().flatten()
        if custom_ids.numel():
            robot_state[custom_ids] = plan.state[custom_ids, : robot_state.shape[1]]
            object_state[custom_ids] = plan.state[custom_ids, robot_state.shape[1]:]
            frame[custom_ids] = plan.frame[custom_ids]

        # reference/physical state initialisation for the others
        others = (~stand & ~custom).nonzero().flatten()
        reference_start = torch.zeros(n, dtype=torch.bool, device=self.device)  # a reference state, not a simulated one
        if others.numel():
            states, frames = self.psi.sample(others.numel()) if self.psi.ready() else (None, None)
            if states is None:
                frames = self._random_frames(clip[others])
                states = self._reference_states(frames)
                reference_start[others] = True
            else:  # seeded (reference) rows get a fresh RSI draw: seeds share no frozen noise
                from_reference = states.isnan().any(-1)
                if from_reference.any():
                    states[from_reference] = self._reference_states(frames[from_reference])
                reference_start[others] = from_reference
            robot_state[others] = states[:, : robot_state.shape[1]]
            object_state[others] = states[:, robot_state.shape[1]:]
            frame[others] = frames
            clip[others] = torch.bucketize(frames, self.clip_end)
        stand_ids = stand.nonzero().flatten()
        if stand_ids.numel():
            robot_state[stand_ids], object_state[stand_ids] = self._stand_states(frame[stand_ids])

        qpos = torch.cat([robot_state[:, : self.layout.robot_nq], object_state[:, :7]], dim=1)
        # PSI/reference states keep the object's angular velocity in world axes; MuJoCo's free joint wants body axes
        object_ang_local = quat_apply_inverse(object_state[:, 3:7], object_state[:, 10:13])
        qvel = torch.cat([robot_state[:, self.layout.robot_nq:], object_state[:, 7:10], object_ang_local], dim=1)
        self.backend.set_state(env_ids, qpos.to(torch.float64), qvel.to(torch.float64))
        self.clip_id[env_ids] = clip
        self.ref_index[env_ids] = frame
        self.warmup_left[env_ids] = torch.where(stand, self.cfg.warmup_frames, 0)
        if custom_ids.numel():
            self.warmup_left[env_ids[custom_ids]] = plan.hold[custom_ids]
        self.episode_length[env_ids] = 0
        self.grip_settle_left[env_ids] = torch.where(reference_start, self.cfg.init.grip_settle_frames, 0)
        self.assisted[env_ids] = (torch.rand(n, generator=self.generator, device=self.device)
                                  < self.cfg.assist.assisted_share).float()
        if self.object_mass_levels is not None:  # a grid level per episode: log-uniform masses
            levels = torch.randint(len(self.object_mass_levels), (n,), generator=self.generator, device=self.device)
            self.object_mass[env_ids] = self.object_mass_levels[levels]
            self.backend.select_body_mass(env_ids, levels)
        self.tracked_steps[env_ids] = 0
        self.start_frame[env_ids] = frame
        self.contact_loss_frames[env_ids] = 0
        self.last_actions[env_ids] = 0.0
        for s in self.episode_sums.values():
            s[env_ids] = 0.0
        self.episode_error_h[env_ids] = 0.0
        self.episode_error_o[env_ids] = 0.0
        self.episode_error_o_source[env_ids] = 0.0
        self.episode_max_error_h[env_ids] = 0.0
        self.episode_max_error_o[env_ids] = 0.0
        self._update_state(None if n == self.num_envs else env_ids)  # env_ids are distinct: n == all of them
        self.warmup_length[env_ids] = self.warmup_left[env_ids]
        self.warmup_start_pos[env_ids] = self.joint_pos[env_ids]
        self.last_ctrl[env_ids] = self.joint_pos[env_ids]  # as the runtime's shaper starts from the measured pose
        self.prev_link_vel[env_ids] = self.link_vel[env_ids]
        self.prev_object_vel[env_ids] = self.object_lin_vel[env_ids]
        self.psi.on_reset(env_ids)
        hold = torch.maximum(torch.minimum(self.joint_pos[env_ids], self.ctrl_high), self.ctrl_low)
        self.randomization.reset(env_ids, hold)  # after every other draw: configs without it keep their stream

    def _random_frames(self, clip: Tensor) -> Tensor:
        lo, hi = self.cfg.init.start_range
        span = (self.clip_end[clip] - self.clip_start[clip]).float()
        uniform = torch.rand(clip.numel(), generator=self.generator, device=self.device)
        if self.cfg.init.failure_weighted:  # a segment in proportion to its failures, uniform inside it
            segments = self.failure_counts.shape[1]
            segment = torch.multinomial(self.failure_counts[clip] + 1.0, 1, generator=self.generator)[:, 0]
            uniform = (segment.float() + uniform) / segments
        fraction = lo + (hi - lo) * uniform
        return self.clip_start[clip] + (fraction * span).long()

    def _count_failures(self, terminated: Tensor) -> None:
        """Terminations per clip segment, for failure-weighted starts (a sum over envs: no host sync)."""
        clip = self.clip_id
        span = (self.clip_end[clip] - self.clip_start[clip]).clamp(min=1).float()
        segments = self.failure_counts.shape[1]
        segment = ((self.ref_index - self.clip_start[clip]).float() / span * segments).long().clamp(0, segments - 1)
        half_life = self.cfg.init.failure_half_life_samples
        if half_life > 0:  # one env step is num_envs samples
            self.failure_counts.mul_(0.5 ** (self.num_envs / half_life))
        self.failure_counts.index_put_((clip, segment), terminated.float(), accumulate=True)

    def _reference_states(self, frames: Tensor) -> Tensor:
        """Robot + object states of the IK reference at `frames`, with joint noise (RSI) on the actuated body
        joints (noise on finger channels would break their mimic joints' couplings)."""
        qpos = self.ref_robot_qpos[frames].clone()
        noisy = self._rsi_noise_qpos
        qpos[:, noisy] += self.cfg.init.joint_noise * torch.randn(len(frames), len(noisy), generator=self.generator,
                                                                   device=self.device)
        qvel = self.ref_robot_qvel[frames]
        obj = torch.cat([self.ref_object_pos[frames], self.ref_object_quat[frames],
                         self.ref_object_lin_vel[frames],
                         self.ref_object_ang_vel[frames]], dim=1)
        return torch.cat([qpos, qvel, obj], dim=1)

    def _stand_states(self, frames: Tensor) -> tuple[Tensor, Tensor]:
        """Default standing robot at the reference root's place and heading, object at its reference pose, each
        perturbed by the init config's stand-start draws (a draw is made only where its size is > 0, so adding a
        draw leaves the random stream of configs without it unchanged)."""
        n = frames.numel()
        lay = self.layout
        init = self.cfg.init
        qpos = self._default_robot_qpos.repeat(n, 1)
        ref_root = self.ref_robot_qpos[frames]
        qpos[:, 0:2] = ref_root[:, 0:2] + self._uniform(n, 2, init.spawn_noise_xy)
        heading = yaw_quat(ref_root[:, 3:7])
        if init.spawn_noise_yaw > 0:
            heading = quat_mul(quat_from_yaw(self._uniform(n, 1, init.spawn_noise_yaw)[:, 0]), heading)
        qpos[:, 3:7] = quat_mul(heading, qpos[:, 3:7])
        if init.stand_joint_noise > 0:
            noisy = self._rsi_noise_qpos
            qpos[:, noisy] += init.stand_joint_noise * torch.randn(n, len(noisy), generator=self.generator,
                                                                   device=self.device)
        robot = torch.cat([qpos, torch.zeros(n, lay.robot_nv, device=self.device)], dim=1)
        obj_pos, obj_quat = self.ref_object_pos[frames].clone(), self.ref_object_quat[frames]
        if init.object_noise_xy > 0:
            obj_pos[:, 0:2] += self._uniform(n, 2, init.object_noise_xy)
        if init.object_noise_yaw > 0:  # about the vertical through the object's origin: a floor object stays put
            obj_quat = quat_mul(quat_from_yaw(self._uniform(n, 1, init.object_noise_yaw)[:, 0]), obj_quat)
        obj = torch.cat([obj_pos, obj_quat, torch.zeros(n, 6, device=self.device)], dim=1)
        return robot, obj

    def _uniform(self, n: int, dims: int, half_width: float) -> Tensor:
        """Uniform draws in [-half_width, half_width] from the env's generator (none made at width 0)."""
        if half_width <= 0:
            return torch.zeros(n, dims, device=self.device)
        return half_width * (2 * torch.rand(n, dims, generator=self.generator, device=self.device) - 1)

    def current_states(self) -> Tensor:
        """Robot + object states of every env, in the PSI buffer layout."""
        lay = self.layout
        qpos, qvel = self.backend.qpos.to(torch.float32), self.backend.qvel.to(torch.float32)
        obj_v = qvel[:, lay.object_dof:lay.object_dof + 6].clone()
        obj_v[:, 3:] = quat_apply(self.object_quat, obj_v[:, 3:])  # store world-frame angular velocity
        return torch.cat([qpos[:, : lay.robot_nq], qvel[:, : lay.robot_nv],
                          qpos[:, lay.object_qpos:lay.object_qpos + 7], obj_v], dim=1)

    # ---- observations -------------------------------------------------------------------------------------------
    def _observations(self) -> dict[str, Tensor]:
        policy = obs_terms.teacher_observation(self)
        groups = {"policy": policy, "critic": torch.cat([policy, obs_terms.critic_extras(self)], dim=-1)}
        if self.cfg.student_obs_terms:
            groups["student"] = obs_terms.student_observation(self)
        return groups


def reference_frame(ref, idx: Tensor) -> ReferenceFrame:
    """The reference at absolute frames `idx` of `ref`'s ref_* tensors (an env, or a timeline laid out like one)."""
    return ReferenceFrame(
        link_pos=ref.ref_link_pos[idx], link_quat_wxyz=ref.ref_link_quat[idx], d_hat=ref.ref_d_hat[idx],
        object_pos=ref.ref_object_pos[idx], object_quat_wxyz=ref.ref_object_quat[idx],
        hand_contact=ref.ref_hand_contact[idx], hand_distance=ref.ref_hand_distance[idx],
        root_pos=ref.ref_robot_qpos[idx, 0:3], root_quat_wxyz=ref.ref_robot_qpos[idx, 3:7],
        joint_pos=ref.ref_joint_pos[idx], joint_state=ref.ref_joint_state[idx], joint_vel=ref.ref_joint_vel[idx],
        link_vel=ref.ref_link_vel[idx], link_rotmat=ref.ref_link_rotmat[idx],
        object_rotmat=ref.ref_object_rotmat[idx], root_rotmat=ref.ref_root_rotmat[idx],
    )


def link_velocities(ref: ReferenceMotion) -> Tensor:
    """(T, L, 3) world linear velocities of a reference's links: central differences of its link positions."""
    if ref.num_frames < 2:
        return torch.zeros_like(ref.link_pos)
    return torch.gradient(ref.link_pos, spacing=1.0 / ref.fps, dim=0)[0]


def object_mass_levels(mass: float, scale: tuple[float, float], step: float = 1.02) -> Tensor | None:
    """The masses (kg) an episode's object may have: `mass` x the scales of a geometric grid (`step` apart) over
    [low, high], the ends included; None when the range is (1, 1) (no randomisation)."""
    lo, hi = scale
    if not 0 < lo <= hi:
        raise UserError(f"env.randomization.object_mass_scale must be 0 < low <= high, not {[lo, hi]}")
    if lo == hi == 1.0:
        return None
    grid = torch.arange(math.floor(math.log(lo, step)), math.ceil(math.log(hi, step)) + 1, dtype=torch.float64)
    scales = torch.unique(torch.pow(step, grid).clamp(lo, hi))
    return (mass * scales).to(torch.float32)


def _subsample(points: Tensor, count: int) -> Tensor:
    """Evenly strided subset of the surface samples (deterministic), for a cheaper d_t."""
    if count <= 0 or points.shape[0] <= count:
        return points
    return points[torch.linspace(0, points.shape[0] - 1, count).round().long()]

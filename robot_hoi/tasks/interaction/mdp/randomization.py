"""Domain randomisation (env_cfg.RandomizationCfg): what a policy for the robot must not depend on.

Per episode (drawn at each env's reset): the object's and the floor's friction, the body motors' PD gains and the
torso's centre of mass, written into that env's rows of the backend's model (write_model_fields: exact, as
MuJoCo's position actuators apply kp and kv inside the physics step; scaling the target instead,
q + s (target - q), would scale kp only within a control step and leave kd untouched), and the actuator delay.
Per step: delayed PD targets (one per physics sub-step), pelvis pushes and observation noise. The object's mass
is drawn by the env itself (mass levels, object_mass_levels). Every draw comes from the env's generator and is
batched over envs; a neutral setting makes no draw, so a config without randomisation keeps its random stream.
"""

from __future__ import annotations

import math

import mujoco
import torch
from torch import Tensor

from robot_hoi.errors import UserError
from robot_hoi.tasks.interaction.env_cfg import RandomizationCfg

TORSO_BODY = "torso_link"
NOISE_KEYS = ("joint_pos_noise", "joint_vel_noise", "imu_rot_noise", "gyro_noise", "tracker_pos_noise",
              "tracker_rot_noise")


def _scaled(value: tuple[float, float]) -> bool:
    return tuple(value) != (1.0, 1.0)


def check(cfg: RandomizationCfg) -> None:
    """One clear error per bad setting, naming its key."""
    def fail(key: str, problem: str) -> UserError:
        return UserError(f"env.randomization.{key} {problem}, not {getattr(cfg, key)!r}")

    for key in ("object_friction_scale", "floor_friction_scale", "kp_scale", "kd_scale"):
        lo, hi = getattr(cfg, key)
        if not 0 < lo <= hi:
            raise fail(key, "must be 0 < low <= high")
    lo, hi = cfg.actuator_delay_s
    if not 0 <= lo <= hi:
        raise fail("actuator_delay_s", "must be 0 <= low <= high (s)")
    lo, hi = cfg.push_interval_s
    if not 0 < lo <= hi:
        raise fail("push_interval_s", "must be 0 < low <= high (s)")
    if not cfg.push_velocity >= 0:
        raise fail("push_velocity", "must be >= 0 (m/s)")
    if len(cfg.torso_com_offset) != 3 or min(cfg.torso_com_offset) < 0:
        raise fail("torso_com_offset", "must be three half-widths >= 0 (m, x y z)")
    for key in NOISE_KEYS:
        if not getattr(cfg, key) >= 0:
            raise fail(key, "must be >= 0")


def variable_fields(cfg: RandomizationCfg) -> tuple[str, ...]:
    """The MjModel arrays this config gives each env its own rows of (the backend prepares them once)."""
    fields: list[str] = []
    if _scaled(cfg.object_friction_scale) or _scaled(cfg.floor_friction_scale):
        fields.append("geom_friction")
    if _scaled(cfg.kp_scale) or _scaled(cfg.kd_scale):
        fields += ["actuator_gainprm", "actuator_biasprm"]
    if any(cfg.torso_com_offset):
        fields.append("body_ipos")
    return tuple(fields)


class DomainRandomization:
    """The per-env draws of one InteractionEnv (state: delays, target history, push timers)."""

    def __init__(self, cfg: RandomizationCfg, env, noise_sources: dict[str, str]):
        check(cfg)
        self.cfg = cfg
        self.env = env
        self.generator = env.generator
        self.device = env.device
        model = env.scene.model
        n = env.num_envs
        # the model's own values in float64: untouched entries go back bit for bit (the CPU physics is float64)
        as_tensor = lambda a: torch.as_tensor(a, dtype=torch.float64, device=self.device)  # noqa: E731
        object_body = env.scene.object_body_id()
        self._object_geoms = torch.as_tensor(model.geom_bodyid == object_body, device=self.device)
        self._friction0 = as_tensor(model.geom_friction)
        body_names = [env.layout.actuator_names[i] for i in env.body_actuator_ids]
        self._body_actuators = torch.as_tensor(
            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name) for name in body_names], device=self.device)
        self._gain0, self._bias0 = as_tensor(model.actuator_gainprm), as_tensor(model.actuator_biasprm)
        self._ipos0 = as_tensor(model.body_ipos)
        self._torso = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, TORSO_BODY)
        if any(cfg.torso_com_offset) and self._torso < 0:
            raise UserError(f"env.randomization.torso_com_offset: the robot has no body {TORSO_BODY!r}")
        # actuator delay in physics steps; the history holds the targets of the last `depth` control steps + this
        physics_dt = env.backend.model.opt.timestep
        self.decimation = env.backend.decimation
        self._delay_steps = [round(s / physics_dt) for s in cfg.actuator_delay_s]
        self.delayed_on = self._delay_steps[1] > 0
        depth = math.ceil(self._delay_steps[1] / self.decimation)
        self.delay = torch.zeros(n, dtype=torch.long, device=self.device)
        self.history = torch.zeros(n, depth + 1, env.num_actions, device=self.device) if self.delayed_on else None
        self._substeps = torch.arange(self.decimation, device=self.device)
        self.push_timer = torch.zeros(n, device=self.device)  # s to the next push
        self.pushes = torch.zeros(n, dtype=torch.long, device=self.device)  # pushes this episode
        self.noise_std = {term: getattr(cfg, key) for term, key in noise_sources.items() if getattr(cfg, key) > 0}

    # ---- per episode ------------------------------------------------------------------------------------------
    def _uniform(self, n: int, low: float, high: float, *shape: int) -> Tensor:
        return low + (high - low) * torch.rand(n, *shape, generator=self.generator, device=self.device)

    def reset(self, env_ids: Tensor, hold: Tensor) -> None:
        """New draws for `env_ids`; `hold` (n, A): the PD targets the motors hold before the first delayed target
        arrives (the reset pose)."""
        cfg, n = self.cfg, env_ids.numel()
        fields: dict[str, Tensor] = {}
        if _scaled(cfg.object_friction_scale) or _scaled(cfg.floor_friction_scale):
            scale = torch.ones(n, self._friction0.shape[0], device=self.device)
            if _scaled(cfg.object_friction_scale):
                scale = torch.where(self._object_geoms, self._uniform(n, *cfg.object_friction_scale)[:, None], scale)
            if _scaled(cfg.floor_friction_scale):
                scale = torch.where(self._object_geoms, scale, self._uniform(n, *cfg.floor_friction_scale)[:, None])
            friction = self._friction0.repeat(n, 1, 1)
            friction[..., 0] *= scale  # sliding only
            fields["geom_friction"] = friction
        if _scaled(cfg.kp_scale) or _scaled(cfg.kd_scale):
            kp = self._uniform(n, *cfg.kp_scale)[:, None]
            kd = self._uniform(n, *cfg.kd_scale)[:, None]
            gain, bias = self._gain0.repeat(n, 1, 1), self._bias0.repeat(n, 1, 1)
            body = self._body_actuators
            gain[:, body, 0] *= kp  # position actuator: force = kp ctrl - kp q - kv qdot
            bias[:, body, 1] *= kp
            bias[:, body, 2] *= kd
            fields["actuator_gainprm"], fields["actuator_biasprm"] = gain, bias
        if any(cfg.torso_com_offset):
            half = torch.as_tensor(cfg.torso_com_offset, dtype=torch.float64, device=self.device)
            ipos = self._ipos0.repeat(n, 1, 1)
            ipos[:, self._torso] += half * (2 * torch.rand(n, 3, generator=self.generator, device=self.device) - 1)
            fields["body_ipos"] = ipos
        if fields:
            self.env.backend.write_model_fields(env_ids, fields)
        if self.delayed_on:
            lo, hi = self._delay_steps
            self.delay[env_ids] = torch.randint(lo, hi + 1, (n,), generator=self.generator, device=self.device)
            self.history[env_ids] = hold[:, None].expand(-1, self.history.shape[1], -1)
        if cfg.push_velocity > 0:
            self.push_timer[env_ids] = self._uniform(n, *cfg.push_interval_s)
            self.pushes[env_ids] = 0

    # ---- per step -----------------------------------------------------------------------------------------------
    def delayed(self, targets: Tensor) -> Tensor:
        """The PD targets the motors see this control step: `targets` (N, A) without a delay, else (N, decimation,
        A), sub-step j holding the newest target that has arrived by then (issued ceil((delay - j) / decimation)
        control steps ago)."""
        if not self.delayed_on:
            return targets
        self.history = torch.cat([targets[:, None], self.history[:, :-1]], dim=1)
        lag = (self.delay[:, None] - self._substeps[None] + self.decimation - 1).div(self.decimation,
                                                                                     rounding_mode="floor")
        lag = lag.clamp(0, self.history.shape[1] - 1)
        return self.history.gather(1, lag[..., None].expand(-1, -1, targets.shape[1]))

    def push(self, dt: float) -> None:
        """Add the pushes due this step to the pelvis velocity (the backend's state, before it steps)."""
        if self.cfg.push_velocity <= 0:
            return
        n = self.push_timer.shape[0]
        self.push_timer -= dt
        due = self.push_timer <= 0
        v = self.cfg.push_velocity
        kick = self._uniform(n, -v, v, 2)
        self.push_timer = torch.where(due, self.push_timer + self._uniform(n, *self.cfg.push_interval_s),
                                      self.push_timer)
        self.pushes += due.long()
        qvel = self.env.backend.qvel  # the free joint's linear velocity (world frame) leads qvel
        qvel[:, 0:2] += torch.where(due[:, None], kick, 0.0).to(qvel.dtype)

    def noisy(self, term: str, value: Tensor) -> Tensor:
        """`value` of observation term `term` with its sensor's noise (unchanged when that noise is off)."""
        std = self.noise_std.get(term)
        if std is None:
            return value
        return value + std * torch.randn(value.shape, generator=self.generator, device=self.device)

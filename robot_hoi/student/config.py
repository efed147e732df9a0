"""Student training configuration: the teacher PPO config plus the Transformer, distillation and option sections.

Torch-free so the CLI can load and validate a config before importing torch. Defaults are InterMimic's student
(Sec. 3.3-3.4, Alg. 1, Table C); the ComplexMimic and SkillMimic-V2 sections default to off and carry their
papers' parameters (ComplexMimic Sec. 4.1; SkillMimic-V2 Tab. 8-9, supp. B.4-B.5).

Options are YAML overlays in configs/train/student_options/ (`--option NAME`), applied before `--set` overrides.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from robot_hoi.errors import UserError
from robot_hoi.paths import CONFIGS_DIR
from robot_hoi.rl.config import TrainConfig
from robot_hoi.tasks.interaction.env_cfg import split_overrides
from robot_hoi.utils.config import apply_overrides, load_yaml_dataclass

STUDENT_CONFIG = CONFIGS_DIR / "train" / "student.yaml"
STUDENT_FAST_CONFIG = CONFIGS_DIR / "train" / "student_fast.yaml"
OPTIONS_DIR = CONFIGS_DIR / "train" / "student_options"
PRESETS = {"paper": STUDENT_CONFIG, "fast": STUDENT_FAST_CONFIG}
DEFAULT_PRESET = "fast"  # what `robot-hoi train student` uses without --preset


@dataclass
class TransformerConfig:
    """InterMimic Sec. 4: a three-layer Transformer encoder, 4 heads, width 256, feed-forward 512."""

    width: int = 256
    heads: int = 4
    layers: int = 3
    feedforward: int = 512
    dropout: float = 0.0
    activation: str = "gelu"  # relu | gelu
    norm_first: bool = True  # pre-norm: stable without learning-rate warm-up
    pooling: str = "mean"  # mean over tokens | first (the proprioception/object token)

    def __post_init__(self) -> None:
        if min(self.width, self.heads, self.layers, self.feedforward) <= 0:
            raise ValueError("student width, heads, layers and feedforward must be positive")
        if self.width % self.heads:
            raise ValueError(f"student width {self.width} is not divisible by heads {self.heads}")
        if self.activation not in ("relu", "gelu"):
            raise ValueError("student activation must be relu or gelu")
        if self.pooling not in ("mean", "first"):
            raise ValueError("student pooling must be mean or first")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError("student dropout must lie in [0, 1)")


@dataclass
class DistillConfig:
    """InterMimic Alg. 1. The student executes its own action with probability min(t / beta, 1) (t = iteration)
    and the teacher's otherwise; the actor loss is w * L_PPO + (1 - w) * L_distill with w = min(t / beta, 1)
    ("schedule"), or lambda_ppo * L_PPO + lambda_kd * L_distill ("fixed", ComplexMimic Eq. 4)."""

    reference: str = "teacher"  # teacher: teacher rollouts are the student's reference (reference distillation)
    beta: int = 100  # DAgger schedule length in iterations; 0 = the student acts from the start
    weights: str = "schedule"  # schedule | fixed
    lambda_ppo: float = 1.0  # fixed weights only
    lambda_kd: float = 1.0
    loss: str = "l2"  # l2: ||a_S - a_T|| (Alg. 1 line 16) | kl: KL(pi_S || pi_T) (ComplexMimic Eq. 3)
    reference_min_frames: int = 30  # a teacher rollout shorter than this drops its clip (teachers filter data)
    reference_failure_margin: int = 10  # frames cut before a teacher's early termination

    def __post_init__(self) -> None:
        if self.reference not in ("teacher", "mocap"):
            raise ValueError("distill.reference must be teacher or mocap")
        if self.weights not in ("schedule", "fixed"):
            raise ValueError("distill.weights must be schedule or fixed")
        if self.loss not in ("l2", "kl"):
            raise ValueError("distill.loss must be l2 or kl")
        if self.beta < 0 or self.lambda_ppo < 0 or self.lambda_kd < 0:
            raise ValueError("distill.beta, lambda_ppo and lambda_kd must be >= 0")
        if self.reference_min_frames < 2 or self.reference_failure_margin < 0:
            raise ValueError("distill.reference_min_frames must be >= 2 and reference_failure_margin >= 0")


@dataclass
class ComplexMimicConfig:
    """ComplexMimic (Sec. 3.1-3.2, 4.1): dual-flow experts, regime routing, KL distillation, difficulty-aware
    sampling. The EMA settings are decays (weight of the old value): the paper's "EMA 0.95 / 0.9"."""

    enabled: bool = False
    imitation_tau: float = 0.25  # strict termination threshold of the imitation expert (m, mean link error)
    interaction_tau: float = 0.5  # relaxed threshold of the interaction expert
    student_tau: float = 0.5  # "for student training we keep tau fixed at 0.5"
    height_map_size: int = 20  # 20 x 20 samples ...
    height_map_spacing: float = 0.08  # ... 8 cm apart, centred on the robot, heading-aligned
    expert_budget_fraction: float = 0.3  # share of --budget spent fine-tuning the two experts per teacher
    interaction_init: str = "teacher"  # teacher: start from the teacher (height-map inputs zero-initialised)
    routing_episodes: int = 4  # imitation-expert evaluation episodes per clip for the routing
    routing_success: float = 0.5  # success rate at or above which a clip is tracking-friendly
    sampling: bool = True  # difficulty-aware sampling of reset clips
    update_every: int = 10  # K: iterations between difficulty updates
    failure_ema_decay: float = 0.95
    return_ema_decay: float = 0.9
    tau_inter: float = 1.0
    tau_intra: float = 1.0
    uniform_mix: float = 0.05  # epsilon of Eq. 9
    improvement_threshold: float = 0.1  # epsilon_u of Eq. 8
    learnability_lambda: float = 1.0  # lambda_u of Eq. 8
    inter_group: bool = True  # ablation switches
    intra_group: bool = True
    learnability_filter: bool = True

    def __post_init__(self) -> None:
        if min(self.imitation_tau, self.interaction_tau, self.student_tau, self.height_map_spacing) <= 0:
            raise ValueError("complexmimic taus and height_map_spacing must be positive")
        if self.height_map_size <= 0 or self.update_every <= 0 or self.routing_episodes <= 0:
            raise ValueError("complexmimic height_map_size, update_every and routing_episodes must be positive")
        if not 0.0 <= self.expert_budget_fraction < 1.0:
            raise ValueError("complexmimic.expert_budget_fraction must lie in [0, 1)")
        if self.interaction_init not in ("teacher", "scratch"):
            raise ValueError("complexmimic.interaction_init must be teacher or scratch")
        for name in ("failure_ema_decay", "return_ema_decay", "uniform_mix", "routing_success"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"complexmimic.{name} must lie in [0, 1]")


@dataclass
class SkillMimicConfig:
    """SkillMimic-V2 (Sec. 4.3-4.6, supp. B.4-B.5, Tab. 8-9): STF initialisation, stitched trajectory graph,
    adaptive trajectory sampling and a frozen behaviour-cloned history encoder."""

    enabled: bool = False
    stf: bool = True  # epsilon-neighbourhood state initialisation with the connection rule
    stitching: bool = True  # stitched trajectory graph across clips
    ats: bool = True  # adaptive trajectory sampling (Eq. 8); off = uniform centroids
    history: bool = True  # history encoder (not exportable: the deploy contract has no history term)
    neighbourhood_probability: float = 0.1  # p_n
    external_probability: float = 0.1  # p_e
    max_masked: int = 10  # N_max
    similarity_threshold: float = 1e-10  # tau of the connection rule
    ats_lambda: float = 10.0  # lambda_s
    class_lambda: float = 5.0  # lambda_c (inter-clip ATS)
    ats_ema_decay: float = 0.5  # smoothing of each start frame's mean reward
    eps_root_pos: float = 0.1
    eps_root_rot: float = 0.1
    eps_root_vel: float = 0.1
    eps_root_ang_vel: float = 0.1
    eps_dof: float = 0.1
    eps_dof_vel: float = 0.1
    eps_obj_pos: float = 0.1
    eps_obj_rot: float = 0.1
    eps_obj_vel: float = 0.1
    eps_obj_ang_vel: float = 0.1
    lambda_pos: float = 20.0  # similarity weights (Tab. 10: position, rotation, object position, relative)
    lambda_rot: float = 20.0
    lambda_obj_pos: float = 1.0
    lambda_rel: float = 20.0
    history_length: int = 60  # k
    history_dim: int = 3  # mu
    history_pretrain_steps: int = 2000
    history_lr: float = 1e-3
    history_batch: int = 256
    lambda_a: float = 1.0  # Eq. 23
    lambda_b: float = 1e-5

    def __post_init__(self) -> None:
        for name in ("neighbourhood_probability", "external_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"skillmimic.{name} must lie in [0, 1]")
        if self.max_masked < 0 or self.history_length < 2 or self.history_dim <= 0:
            raise ValueError("skillmimic.max_masked >= 0, history_length >= 2, history_dim > 0")
        if self.history_pretrain_steps < 0 or self.history_batch <= 0 or self.history_lr <= 0:
            raise ValueError("skillmimic history pre-training settings must be positive")
        if not 0.0 <= self.ats_ema_decay < 1.0:
            raise ValueError("skillmimic.ats_ema_decay must lie in [0, 1)")


@dataclass
class StabilityConfig:
    """Neighbouring checkpoints that agree (off by default; --option stable). The student that is evaluated,
    selected (model_best.pt) and exported is an exponential moving average of the trained weights, and the actor's
    learning rate decays, so late updates move it less. Measured without them on lift_place: checkpoints 25
    iterations apart scored 1.00 / 0.40 / 0.20 in sim2sim."""

    ema_decay: float = 0.0  # weight of the old average per iteration (0: off; the average is the last weights)
    lr_half_life: int = 0  # iterations over which ppo.actor_lr halves (0: constant)
    lr_floor: float = 0.1  # the decayed rate stops at this fraction of ppo.actor_lr

    def __post_init__(self) -> None:
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError("stability.ema_decay must lie in [0, 1)")
        if self.lr_half_life < 0 or not 0.0 < self.lr_floor <= 1.0:
            raise ValueError("stability.lr_half_life must be >= 0 and lr_floor in (0, 1]")

    def ema_weight(self, updates: int) -> float:
        """Decay of the average's update number `updates` (1, 2, ...): ramped in as (1 + n) / (10 + n), so the
        first average is not dominated by the untrained start."""
        return min(self.ema_decay, (1.0 + updates) / (10.0 + updates))

    def lr_scale(self, iteration: int) -> float:
        if self.lr_half_life <= 0:
            return 1.0
        return max(self.lr_floor, 0.5 ** (iteration / self.lr_half_life))


@dataclass
class StudentTrainConfig(TrainConfig):
    """TrainConfig (model = critic settings, ppo, runner) + the student sections. model.actor_hidden_dims is
    unused: the actor is the Transformer of `student`."""

    eval_episodes: int = 4  # after training: student vs teachers, episodes per clip (0 skips)
    num_envs: int | None = None  # student (and teacher rollout) envs; None: the teachers' (their task.json).
    # --set env.num_envs=N wins over both
    student: TransformerConfig = field(default_factory=TransformerConfig)
    distill: DistillConfig = field(default_factory=DistillConfig)
    complexmimic: ComplexMimicConfig = field(default_factory=ComplexMimicConfig)
    skillmimic: SkillMimicConfig = field(default_factory=SkillMimicConfig)
    stability: StabilityConfig = field(default_factory=StabilityConfig)


def option_path(name: str) -> Path:
    path = Path(name)
    if path.suffix in (".yaml", ".yml") and path.is_file():
        return path
    candidate = OPTIONS_DIR / f"{name}.yaml"
    if not candidate.is_file():
        known = sorted(p.stem for p in OPTIONS_DIR.glob("*.yaml"))
        raise UserError(f"--option {name!r}: no such option (known: {', '.join(known)})")
    return candidate


def option_overrides(name: str) -> list[str]:
    """An option file (a nested partial config) as dotted overrides, e.g. ["distill.loss=\"kl\""]."""
    path = option_path(name)
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise UserError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(data, dict):
        raise UserError(f"{path}: an option is a mapping of config sections")
    return [f"{key}={json.dumps(value)}" for key, value in _flatten(data)]


def _flatten(data: dict, prefix: str = "") -> list[tuple[str, Any]]:
    items: list[tuple[str, Any]] = []
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            items += _flatten(value, dotted + ".")
        else:
            items.append((dotted, value))
    return items


def load_student_config(path: str | Path = STUDENT_FAST_CONFIG, options: list[str] | None = None,
                        overrides: list[str] | None = None) -> tuple[StudentTrainConfig, list[str]]:
    """The config from `path`, then each option, then `overrides`. Returns it with the environment's overrides
    (keys starting with "env." or "retarget.", tasks.interaction.env_cfg.split_overrides), which belong to the
    environment config."""
    items = [item for name in options or [] for item in option_overrides(name)] + list(overrides or [])
    env, train = split_overrides(items)
    cfg = apply_overrides(load_yaml_dataclass(StudentTrainConfig, path), train, source=str(path))
    if cfg.num_envs is not None and cfg.num_envs <= 0:
        raise UserError(f"{path}: num_envs must be positive or null, not {cfg.num_envs}")
    return cfg, ([f"num_envs={cfg.num_envs}"] if cfg.num_envs is not None else []) + env

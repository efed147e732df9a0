"""PPO training configuration: dataclasses whose defaults are InterMimic's teacher settings (supp. Table C).

Table C gives gamma, GAE lambda, entropy 0, Adam, actor/critic learning rates, minibatch 16384, horizon 32 and
the action-bound loss coefficient 10. Values Table C leaves out follow the InterMimic training config it was run
with (rl_games): 6 mini-epochs, ratio clip 0.2, no value clipping, inputs normalised, advantages normalised,
fixed Gaussian std exp(-2.9) ~ 0.055, ReLU MLPs [1024, 1024, 512] for both actor and critic, and the bound
loss applied past |mean| > 1.1. Table C's maximum episode length (300 steps) is an environment setting.

Torch-free so the CLI can load and validate a config before importing torch.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from robot_hoi.paths import CONFIGS_DIR
from robot_hoi.utils.config import load_dataclass, load_yaml_dataclass

ACTIVATIONS = ("relu", "elu", "tanh")
DEFAULT_PPO_CONFIG = CONFIGS_DIR / "train" / "ppo.yaml"
FAST_PPO_CONFIG = CONFIGS_DIR / "train" / "ppo_fast.yaml"
PRESETS = {"paper": DEFAULT_PPO_CONFIG, "fast": FAST_PPO_CONFIG}  # robot-hoi train --preset


@dataclass
class ActorCriticConfig:
    actor_hidden_dims: list[int] = field(default_factory=lambda: [1024, 1024, 512])
    critic_hidden_dims: list[int] = field(default_factory=lambda: [1024, 1024, 512])
    activation: str = "relu"
    init_log_std: float = -2.9  # per action dim; std = exp(init_log_std)
    learn_std: bool = False  # InterMimic/ASE keep the std fixed
    normalize_obs: bool = True  # running mean/std of the actor and critic inputs
    obs_clip: float = 5.0  # normalised inputs are clamped to [-obs_clip, obs_clip]

    def __post_init__(self) -> None:
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation {self.activation!r} is not one of {list(ACTIVATIONS)}")
        if not self.actor_hidden_dims or not self.critic_hidden_dims:
            raise ValueError("hidden dims must list at least one layer")
        if min(self.actor_hidden_dims + self.critic_hidden_dims) <= 0:
            raise ValueError("hidden layer sizes must be positive")
        if self.obs_clip <= 0:
            raise ValueError("obs_clip must be positive")


@dataclass
class PPOConfig:
    horizon: int = 32  # env steps per iteration and env (Table C "horizon length H")
    gamma: float = 0.99
    lam: float = 0.95  # GAE lambda
    actor_lr: float = 2e-5
    critic_lr: float = 1e-4
    minibatch_size: int | None = (
        16384  # samples per minibatch; exactly one of this and num_minibatches is set
    )
    num_minibatches: int | None = None  # alternative: split each rollout into this many minibatches
    num_epochs: int = 6  # passes over the rollout per iteration
    clip_ratio: float = 0.2
    clip_value_loss: bool = False
    value_clip: float = 0.2  # used only with clip_value_loss
    bound_loss_coef: float = 10.0
    action_bound: float = 1.1  # penalise the action mean outside [-action_bound, action_bound]
    entropy_coef: float = 0.0
    max_grad_norm: float | None = 1.0  # per network; null disables clipping
    normalize_advantage: bool = True  # over the whole rollout, before the mini-epochs
    desired_kl: float | None = None  # set to enable the adaptive actor learning rate
    min_lr: float = 1e-6  # bounds of the adaptive actor learning rate
    max_lr: float = 1e-2

    def __post_init__(self) -> None:
        if (self.minibatch_size is None) == (self.num_minibatches is None):
            raise ValueError("set exactly one of minibatch_size and num_minibatches")
        for name in ("horizon", "num_epochs", "minibatch_size", "num_minibatches"):
            value = getattr(self, name)
            if value is not None and value <= 0:
                raise ValueError(f"{name} must be positive, got {value}")
        if not 0.0 <= self.gamma <= 1.0 or not 0.0 <= self.lam <= 1.0:
            raise ValueError("gamma and lam must lie in [0, 1]")
        if self.actor_lr <= 0 or self.critic_lr <= 0:
            raise ValueError("learning rates must be positive")
        if self.clip_ratio <= 0 or self.action_bound <= 0:
            raise ValueError("clip_ratio and action_bound must be positive")


@dataclass
class RunnerConfig:
    actor_obs_groups: list[str] = field(default_factory=lambda: ["policy"])  # concatenated in this order
    critic_obs_groups: list[str] = field(default_factory=lambda: ["critic"])
    # Raw observation groups kept in the rollout for PPO.extra_actor_loss (e.g. ["teacher"] for distillation).
    extra_obs_groups: list[str] = field(default_factory=list)
    save_interval: int = 500  # iterations between checkpoints (one is always written at the end)
    keep_last: int | None = 5  # periodic checkpoints kept on disk; null keeps all
    episode_window: int = 100  # finished episodes averaged for mean return / length
    tensorboard: bool = True
    progress: bool = True  # rich progress bar with ETA against the budget
    physics_check_interval: int = 50  # iterations between reads of the physics' overflow flags (one host sync)
    # torch CPU threads for the PPO update; null: the physics pool's threads (idle while the update runs). The
    # rollout keeps --torch-threads (1: its 64-row ops lose more to hand-offs than they gain). Measured (2 vCPU,
    # fast preset, 3072 samples x 5 epochs): 1 thread 663 ms, 2 threads 409 ms per update.
    update_threads: int | None = None
    # In-training evaluation (0: off): every eval_interval iterations the run's evaluator (robot-hoi train's: the
    # randomized evaluation protocol on validation seeds, robot_hoi.rl.evaluation) scores the policy mean on
    # eval_episodes episodes. Eval/* scalars and eval_curve.jsonl record it against training time, and the best so far
    # (eval_curve.eval_rank: success, then interaction success, then tracked duration) is kept as model_best.pt: the
    # policy `eval`, `export` and distillation take from a run.
    eval_interval: int = 500
    eval_episodes: int = 16

    def __post_init__(self) -> None:
        if self.eval_interval < 0 or self.eval_episodes <= 0:
            raise ValueError("eval_interval must be >= 0 (0: off) and eval_episodes positive")
        if not self.actor_obs_groups or not self.critic_obs_groups:
            raise ValueError("actor_obs_groups and critic_obs_groups must name at least one group")
        if self.save_interval <= 0 or self.episode_window <= 0 or self.physics_check_interval <= 0:
            raise ValueError("save_interval, episode_window and physics_check_interval must be positive")
        if self.keep_last is not None and self.keep_last <= 0:
            raise ValueError("keep_last must be positive or null")
        if self.update_threads is not None and self.update_threads <= 0:
            raise ValueError("update_threads must be positive or null")


@dataclass
class TrainConfig:
    seed: int = 1
    model: ActorCriticConfig = field(default_factory=ActorCriticConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    runner: RunnerConfig = field(default_factory=RunnerConfig)

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str, source: str = "checkpoint config") -> TrainConfig:
        return load_dataclass(cls, json.loads(text), source)


def load_train_config(
    path: str | Path = DEFAULT_PPO_CONFIG, overrides: list[str] | None = None
) -> TrainConfig:
    """Load a training YAML (e.g. configs/train/ppo.yaml) strictly, then apply "a.b=value" overrides."""
    return load_yaml_dataclass(TrainConfig, path, overrides)

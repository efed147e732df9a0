"""The student: a Transformer encoder over keyframe tokens (InterMimic Sec. 3.4) with a teacher-style MLP critic.

Actor: normalised observation -> token 0 (proprioception/object) + one token per reference keyframe
(robot_hoi.student.tokens) -> linear projections + learned type and position embeddings -> Transformer encoder
(pre-norm, no causal mask: 5 tokens attend to each other) -> pooled -> Gaussian action mean. The std is
state-independent (fixed or learned, as the teachers'). Critic: MLP on the privileged "critic" group.

StudentActorCritic keeps ActorCritic's interface (PPO, checkpoints and export use it unchanged); only the networks
differ, so it subclasses ActorCritic and builds its own modules instead of the MLP actor.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from robot_hoi.rl.config import ActorCriticConfig
from robot_hoi.rl.models import ActorCritic, build_mlp
from robot_hoi.rl.normalizer import RunningNormalizer
from robot_hoi.student.config import TransformerConfig
from robot_hoi.student.tokens import TokenLayout


class TransformerActor(nn.Module):
    """Normalised observation (N, obs_dim) -> action mean (N, num_actions)."""

    def __init__(self, layout: TokenLayout, num_actions: int, cfg: TransformerConfig) -> None:
        super().__init__()
        self.layout = layout
        d = cfg.width
        self.register_buffer("state_index", torch.tensor(layout.state_index, dtype=torch.long), persistent=False)
        self.state_proj = nn.Linear(len(layout.state_index), d)
        self.num_tokens = 1 + layout.num_keyframes
        if layout.num_keyframes:
            self.register_buffer("keyframe_index", torch.tensor(layout.keyframe_index, dtype=torch.long),
                                 persistent=False)
            self.keyframe_proj = nn.Linear(layout.keyframe_width, d)
        # token type (0 = state, 1 = keyframe) and position (0 = state, 1 + k = keyframe k)
        self.type_embedding = nn.Parameter(torch.zeros(2, d))
        self.position_embedding = nn.Parameter(torch.zeros(self.num_tokens, d))
        nn.init.normal_(self.type_embedding, std=0.02)
        nn.init.normal_(self.position_embedding, std=0.02)
        self.register_buffer("token_type", torch.tensor([0] + [1] * layout.num_keyframes), persistent=False)
        layer = nn.TransformerEncoderLayer(d, cfg.heads, cfg.feedforward, dropout=cfg.dropout,
                                           activation=cfg.activation, batch_first=True, norm_first=cfg.norm_first)
        self.encoder = nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)
        self.final_norm = nn.LayerNorm(d) if cfg.norm_first else nn.Identity()
        self.pooling = cfg.pooling
        self.head = nn.Linear(d, num_actions)
        nn.init.orthogonal_(self.head.weight, gain=0.01)  # initial mean ~ 0: the env's default pose
        nn.init.zeros_(self.head.bias)
        for proj in (self.state_proj, getattr(self, "keyframe_proj", None)):
            if proj is not None:
                nn.init.xavier_uniform_(proj.weight, gain=1.0 / math.sqrt(2.0))
                nn.init.zeros_(proj.bias)

    def tokens(self, x: Tensor) -> Tensor:
        """(N, obs_dim) -> (N, 1 + K, width) with embeddings added."""
        state = self.state_proj(x.index_select(-1, self.state_index)).unsqueeze(1)
        if self.layout.num_keyframes:
            keyframes = self.keyframe_proj(x[:, self.keyframe_index])  # (N, K, F) -> (N, K, d)
            state = torch.cat([state, keyframes], dim=1)
        return state + self.type_embedding[self.token_type] + self.position_embedding

    def forward(self, x: Tensor) -> Tensor:
        h = self.final_norm(self.encoder(self.tokens(x)))
        pooled = h.mean(dim=1) if self.pooling == "mean" else h[:, 0]
        return self.head(pooled)


class StudentActorCritic(ActorCritic):
    def __init__(self, layout: TokenLayout, num_critic_obs: int, num_actions: int, student: TransformerConfig,
                 cfg: ActorCriticConfig) -> None:
        nn.Module.__init__(self)  # ActorCritic's own __init__ would build the MLP actor we replace
        self.num_actor_obs = layout.obs_dim
        self.num_critic_obs = num_critic_obs
        self.num_actions = num_actions
        self.cfg = cfg
        self.student_cfg = student
        if cfg.normalize_obs:
            self.actor_normalizer: nn.Module = RunningNormalizer(layout.obs_dim, clip=cfg.obs_clip)
            self.critic_normalizer: nn.Module = RunningNormalizer(num_critic_obs, clip=cfg.obs_clip)
        else:
            self.actor_normalizer = nn.Identity()
            self.critic_normalizer = nn.Identity()
        self.actor = TransformerActor(layout, num_actions, student)
        self.critic = build_mlp(num_critic_obs, cfg.critic_hidden_dims, 1, cfg.activation, out_gain=1.0)
        log_std = torch.full((num_actions,), float(cfg.init_log_std))
        if cfg.learn_std:
            self.log_std = nn.Parameter(log_std)
        else:
            self.register_buffer("log_std", log_std)

    @property
    def layout(self) -> TokenLayout:
        return self.actor.layout

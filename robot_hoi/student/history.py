"""SkillMimic-V2's history encoder (Sec. 4.6, supp. B.5), pre-trained by behaviour cloning and then frozen.

    h_t = theta(s_{t-k}, ..., s_{t-1})                   three 1-D convolutions + a linear layer -> mu dims (21)
    s_{t+1} = psi([c, s_t, h_t])                          three-layer MLP predicting the next state       (22)
    L = lambda_a |s_{t+1} - psi(.)|^2 + lambda_b |h_t|^2                                                    (23)

trained on the reference trajectories (c = the clip, one-hot). The state s is the deployable proprioception and
object pose (the student observation's projected_gravity, base_ang_vel, joint_pos, joint_vel, object_pos,
object_rot terms), so the same features come from the reference (through the observation terms' own math) and
from the running env. Before the episode's k-th step the history is padded with its first state.
"""

from __future__ import annotations

from types import SimpleNamespace

import torch
from torch import Tensor, nn

from robot_hoi.student.config import SkillMimicConfig
from robot_hoi.tasks.interaction.mdp import observations as obs_terms
from robot_hoi.utils.torch_rot import quat_to_matrix, yaw_quat

HISTORY_TERMS = ("projected_gravity", "base_ang_vel", "joint_pos", "joint_vel", "object_pos", "object_rot")


def feature_index(obs_spec: list[dict]) -> Tensor:
    """Indices of the history terms inside the student observation."""
    index, offset = [], 0
    for term in obs_spec:
        if term["name"] in HISTORY_TERMS:
            index.extend(range(offset, offset + int(term["size"])))
        offset += int(term["size"])
    return torch.tensor(index, dtype=torch.long)


def reference_features(env, reference) -> Tensor:
    """(T, F) history features of a reference motion, computed by the student observation terms."""
    lay = env.layout
    qpos, qvel = reference.robot_qpos, reference.robot_qvel
    frames = qpos.shape[0]
    root_quat = qpos[:, 3:7]
    state = SimpleNamespace(  # the state attributes the terms read, as InteractionEnv._update_state sets them
        num_envs=frames, device=qpos.device, root_pos=qpos[:, 0:3], root_quat=root_quat, root_ang_vel=qvel[:, 3:6],
        root_rotmat=quat_to_matrix(root_quat), heading_matrix=quat_to_matrix(yaw_quat(root_quat)),
        joint_pos=reference.joint_pos, default_joint_pos=env.default_joint_pos.to(qpos.device),
        joint_vel=qvel[:, torch.as_tensor(lay.actuator_dof)], body_actuator_ids=env.body_actuator_ids,
        object_pos=reference.object_pos, object_quat=reference.object_quat_wxyz,
        object_rotmat=quat_to_matrix(reference.object_quat_wxyz))
    return torch.cat([obs_terms.STUDENT_TERMS[name](state) for name in HISTORY_TERMS], dim=-1)


class HistoryEncoder(nn.Module):
    """theta: (N, k, F) past states -> (N, mu); inputs normalised with the demonstrations' statistics."""

    def __init__(self, num_features: int, length: int, dim: int, channels: int = 32) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(num_features))
        self.register_buffer("std", torch.ones(num_features))
        self.convs = nn.Sequential(
            nn.Conv1d(num_features, channels, 3, stride=2, padding=1), nn.ELU(),
            nn.Conv1d(channels, channels, 3, stride=2, padding=1), nn.ELU(),
            nn.Conv1d(channels, channels, 3, stride=2, padding=1), nn.ELU(),
        )
        with torch.no_grad():
            flat = self.convs(torch.zeros(1, num_features, length)).numel()
        self.out = nn.Linear(flat, dim)
        self.length, self.dim = length, dim

    def forward(self, history: Tensor) -> Tensor:
        x = ((history - self.mean) / self.std).transpose(1, 2)
        return self.out(self.convs(x).flatten(1))


def windows(features: Tensor, length: int) -> tuple[Tensor, Tensor, Tensor]:
    """For t = 0 .. T-2: (history s_{t-k}..s_{t-1} padded with s_0, s_t, s_{t+1})."""
    frames = features.shape[0]
    t = torch.arange(frames - 1)
    past = (t[:, None] - length + torch.arange(length)[None]).clamp(min=0)
    return features[past], features[t], features[t + 1]


def pretrain(encoder: HistoryEncoder, sequences: list[Tensor], cfg: SkillMimicConfig, seed: int = 0
             ) -> list[float]:
    """Eq. 21-23 on the demonstrations (one sequence of features per clip); returns the loss per 100 steps.
    The encoder is frozen afterwards."""
    generator = torch.Generator().manual_seed(seed)
    everything = torch.cat(sequences)
    encoder.mean.copy_(everything.mean(0))
    encoder.std.copy_(everything.std(0).clamp(min=1e-3))
    data = [windows(seq, encoder.length) for seq in sequences]
    past = torch.cat([d[0] for d in data])
    now, after = torch.cat([d[1] for d in data]), torch.cat([d[2] for d in data])
    condition = torch.cat([torch.nn.functional.one_hot(torch.full((d[1].shape[0],), i), len(sequences)).float()
                           for i, d in enumerate(data)])
    features = now.shape[1]
    predictor = nn.Sequential(nn.Linear(len(sequences) + features + encoder.dim, 256), nn.ReLU(),
                              nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, features))
    optimizer = torch.optim.Adam([*encoder.parameters(), *predictor.parameters()], lr=cfg.history_lr)
    scale = encoder.std
    losses, running = [], 0.0
    encoder.train()
    for step in range(cfg.history_pretrain_steps):
        idx = torch.randint(now.shape[0], (min(cfg.history_batch, now.shape[0]),), generator=generator)
        h = encoder(past[idx])
        prediction = predictor(torch.cat([condition[idx], (now[idx] - encoder.mean) / scale, h], dim=-1))
        target = (after[idx] - encoder.mean) / scale
        loss = cfg.lambda_a * (prediction - target).square().sum(-1).mean() + cfg.lambda_b * h.square().sum(-1).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        running += float(loss.detach())
        if (step + 1) % 100 == 0:
            losses.append(running / 100)
            running = 0.0
    encoder.eval()
    encoder.requires_grad_(False)
    return losses


class HistoryProvider:
    """Observation provider: h_t of the frozen encoder from the last k history features of each env."""

    def __init__(self, encoder: HistoryEncoder, index: Tensor, num_envs: int) -> None:
        self.encoder, self.index = encoder, index
        self.dim = encoder.dim
        self.buffer = torch.zeros(num_envs, encoder.length, index.numel())

    def fresh(self, num_envs: int) -> HistoryProvider:
        """The same encoder with its own history buffers, for another env."""
        return HistoryProvider(self.encoder, self.index, num_envs)

    @torch.no_grad()
    def __call__(self, env, obs: dict[str, Tensor], reset: Tensor) -> Tensor:
        """On the observations' device (the encoder and buffers move there once); no host sync."""
        student = obs["student"]
        if self.buffer.device != student.device:
            self.encoder.to(student.device)
            self.index, self.buffer = self.index.to(student.device), self.buffer.to(student.device)
        current = student[:, self.index]
        if reset is not None:
            fresh = current[:, None].expand(-1, self.buffer.shape[1], -1)
            self.buffer = torch.where(reset.to(student.device)[:, None, None], fresh, self.buffer)
        h = self.encoder(self.buffer)
        self.buffer = torch.cat([self.buffer[:, 1:], current[:, None]], dim=1)
        return h

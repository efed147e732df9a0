"""Physical State Initialization (InterMimic Sec. 3.2, supp. E.2).

A FIFO buffer of initial states: it starts with reference frames (RSI: the env draws their state, with fresh
noise, each time one is sampled; stored as NaN rows) spread evenly over every clip, and admits simulated states
whose discounted return over the following `horizon` steps, per step, is above the running mean of such returns
by `return_threshold` running standard deviations. A fixed threshold does not fit: the per-step reward scale
depends on the reward formulation and on how far training is. Candidates are taken sparsely: each env starts
tracking a candidate with probability `update_probability` per step (the paper's 0.005 per rollout), so the buffer
refreshes slowly and stays cheap.
"""

from __future__ import annotations

import torch
from torch import Tensor

from robot_hoi.tasks.interaction.env_cfg import PsiCfg


class PsiBuffer:
    def __init__(self, cfg: PsiCfg, state_dim: int, generator: torch.Generator, gamma: float = 0.99,
                 horizon: int = 32):
        self.cfg = cfg
        self.gamma = gamma
        self.horizon = horizon
        self.generator = generator
        self.device = generator.device  # the env's device
        self.states = torch.zeros(cfg.buffer_size, state_dim, device=self.device)
        self.frames = torch.zeros(cfg.buffer_size, dtype=torch.long, device=self.device)
        self.size = 0
        self.head = 0
        self.admitted = 0
        self.return_mean, self.return_var = 0.0, 0.0  # running statistics of candidate returns (per step)
        self.candidates_seen = 0
        self._cand_state: Tensor | None = None

    def __len__(self) -> int:
        return self.size

    def ready(self) -> bool:
        return self.cfg.enabled and self.size > 0 and bool(
            torch.rand(1, generator=self.generator, device=self.device).item() < self.cfg.sample_probability)

    def push(self, states: Tensor, frames: Tensor) -> None:
        """FIFO insert: the oldest states are overwritten first."""
        n = states.shape[0]
        if n == 0:
            return
        idx = (self.head + torch.arange(n, device=self.device)) % self.cfg.buffer_size
        self.states[idx], self.frames[idx] = states, frames
        self.head = int((self.head + n) % self.cfg.buffer_size)
        self.size = min(self.size + n, self.cfg.buffer_size)

    def sample(self, n: int) -> tuple[Tensor, Tensor]:
        idx = torch.randint(self.size, (n,), generator=self.generator, device=self.device)
        return self.states[idx].clone(), self.frames[idx].clone()

    def seed_from_reference(self, frames: Tensor) -> None:
        """Reference frames (all clips), evenly strided down to the buffer size; their states are NaN rows that
        the env fills with a fresh reference-state draw when they are sampled."""
        if len(frames) > self.cfg.buffer_size:
            frames = frames[torch.linspace(0, len(frames) - 1, self.cfg.buffer_size, device=frames.device).long()]
        self.push(torch.full((len(frames), self.states.shape[1]), float("nan"), device=self.device), frames)

    # ---- candidate tracking, called by the env every step ----------------------------------------------------------
    def _ensure(self, env) -> None:
        if self._cand_state is None:
            n, device = env.num_envs, self.device
            self._cand_state = torch.zeros(n, self.states.shape[1], device=device)
            self._cand_frame = torch.zeros(n, dtype=torch.long, device=device)
            self._cand_return = torch.zeros(n, device=device)
            self._cand_steps = torch.zeros(n, dtype=torch.long, device=device)
            self._cand_active = torch.zeros(n, dtype=torch.bool, device=device)

    def observe(self, env, reward: Tensor, done: Tensor) -> None:
        if not self.cfg.enabled:
            return
        self._ensure(env)
        active = self._cand_active
        self._cand_return += torch.where(active, reward * self.gamma ** self._cand_steps.float(), 0.0)
        self._cand_steps += active.long()
        finished = active & (self._cand_steps >= self.horizon) & ~done
        if finished.any():
            norm = (1 - self.gamma ** self.horizon) / (1 - self.gamma)
            per_step = self._cand_return[finished] / norm
            good = finished.clone()
            good[finished] = self.admit(per_step)
            self.push(self._cand_state[good], self._cand_frame[good])
            self.admitted += int(good.sum())
        self._cand_active &= ~(finished | done)
        start = ~self._cand_active & ~done & (env.warmup_left == 0) & (
            torch.rand(env.num_envs, generator=self.generator, device=self.device) < self.cfg.update_probability)
        if start.any():
            self._cand_state[start] = env.current_states()[start]
            self._cand_frame[start] = env.ref_index[start]
            self._cand_return[start] = 0.0
            self._cand_steps[start] = 0
            self._cand_active |= start

    def admit(self, per_step_returns: Tensor) -> Tensor:
        """Which candidates enter: above the running mean by return_threshold standard deviations. The statistics
        are updated with these returns afterwards (Welford / Chan merge); the first batch only sets them."""
        n = per_step_returns.numel()
        std = self.return_var ** 0.5
        decide = self.candidates_seen > 0
        keep = per_step_returns > self.return_mean + self.cfg.return_threshold * std if decide else \
            torch.zeros(n, dtype=torch.bool, device=self.device)
        mean_b = float(per_step_returns.mean())
        var_b = float(per_step_returns.var(unbiased=False)) if n > 1 else 0.0
        total = self.candidates_seen + n
        delta = mean_b - self.return_mean
        self.return_var = (self.return_var * self.candidates_seen + var_b * n
                           + delta * delta * self.candidates_seen * n / total) / total
        self.return_mean += delta * n / total
        self.candidates_seen = total
        return keep

    def on_reset(self, env_ids: Tensor) -> None:
        if self._cand_state is not None:
            self._cand_active[env_ids] = False

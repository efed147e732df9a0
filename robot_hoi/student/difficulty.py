"""ComplexMimic's difficulty-aware sampling (Sec. 3.2, Eq. 5-9) of the motions (clips) envs reset to.

Every K iterations, for each motion m with finished episodes in that window:
    f_k(m) = share of them that failed (1 - success; one evaluation episode gives the paper's binary indicator)
    D_k(m) = (1 - beta) D_{k-1}(m) + beta f_k(m)                    difficulty (EMA; decay = 1 - beta)
    R_k(m) = mean episode return;  Delta R_k(m) = R_k(m) - R_{k-1}(m)
    I_k(m) = (1 - eta) I_{k-1}(m) + eta Delta R_k(m)                learnability (EMA; decay = 1 - eta)
Sampling:
    D_cls(c) = mean_{m in G_c} D(m)                                  (5)
    p(c)     = softmax_c(tau_inter * D_cls(c))                        (6)
    u(m)     = exp(-lambda_u * max(0, eps_u - I(m)))                  (8)
    s(m)     = D(m) + log u(m)
    p(m | c) = softmax_{m in G_c}(tau_intra * s(m))                   (7)
    p(m)     = (1 - eps) p(c(m)) p(m | c(m)) + eps / |M|              (9)
Ablations: without inter-group sampling p(c) = |G_c| / |M|; without intra-group prioritisation p(m | c) is
uniform; without the learnability filter s(m) = D(m). The evaluation is the training episodes of the window
(free, on-policy) rather than separate evaluation rollouts.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from robot_hoi.student.config import ComplexMimicConfig


def ema(old: Tensor, new: Tensor, decay: float) -> Tensor:
    return decay * old + (1.0 - decay) * new


def group_means(values: Tensor, group_of: Tensor, num_groups: int) -> Tensor:
    """Eq. 5: mean of `values` over each group's members (groups without members: 0)."""
    sums = torch.zeros(num_groups).index_add_(0, group_of, values)
    counts = torch.zeros(num_groups).index_add_(0, group_of, torch.ones_like(values))
    return sums / counts.clamp(min=1)


def learnability(improvement: Tensor, threshold: float, strength: float) -> Tensor:
    """Eq. 8: u(m) = exp(-lambda_u * max(0, eps_u - I(m))); 1 for motions improving by at least eps_u."""
    return torch.exp(-strength * (threshold - improvement).clamp(min=0.0))


def group_softmax(scores: Tensor, group_of: Tensor, num_groups: int) -> Tensor:
    """softmax of `scores` within each group (Eq. 7's normalisation over m' in G_c)."""
    shifted = scores - scores.max()
    weights = torch.exp(shifted)
    totals = torch.zeros(num_groups).index_add_(0, group_of, weights)
    return weights / totals[group_of]


def motion_probabilities(difficulty: Tensor, improvement: Tensor, group_of: Tensor, num_groups: int,
                         cfg: ComplexMimicConfig) -> Tensor:
    """Eq. 5-9: the probability of resetting an env to each motion."""
    num = difficulty.numel()
    present = torch.zeros(num_groups).index_add_(0, group_of, torch.ones(num)) > 0
    if cfg.inter_group:
        logits = cfg.tau_inter * group_means(difficulty, group_of, num_groups)
        logits = torch.where(present, logits, torch.full_like(logits, -torch.inf))
        p_group = torch.softmax(logits, dim=0)
    else:
        p_group = torch.zeros(num_groups).index_add_(0, group_of, torch.ones(num)) / num
    score = difficulty.clone()
    if cfg.learnability_filter:
        score = score + torch.log(learnability(improvement, cfg.improvement_threshold, cfg.learnability_lambda))
    if not cfg.intra_group:
        score = torch.zeros_like(score)
    p_within = group_softmax(cfg.tau_intra * score, group_of, num_groups)
    return (1.0 - cfg.uniform_mix) * p_group[group_of] * p_within + cfg.uniform_mix / num


class DifficultyAwareSampler:
    """Per-motion difficulty and learnability from finished episodes; `probabilities()` for the reset clips."""

    def __init__(self, group_of: list[int], cfg: ComplexMimicConfig) -> None:
        self.cfg = cfg
        self.group_of = torch.as_tensor(group_of, dtype=torch.long)
        self.num_groups = int(self.group_of.max()) + 1
        num = len(group_of)
        self.difficulty = torch.zeros(num)
        self.improvement = torch.zeros(num)
        self.last_return = torch.full((num,), float("nan"))
        self.updates = 0
        self._clear_window()

    def _clear_window(self) -> None:
        num = self.group_of.numel()
        self._failures, self._returns, self._episodes = torch.zeros(num), torch.zeros(num), torch.zeros(num)

    def observe(self, batch) -> None:
        """Episodes that just ended (student_env.EpisodeBatch)."""
        clip = batch.clip.long()
        self._failures.index_add_(0, clip, 1.0 - batch.success.float())
        self._returns.index_add_(0, clip, batch.ret.float())
        self._episodes.index_add_(0, clip, torch.ones(clip.numel()))

    def update(self, reduce: Callable[[Tensor], Tensor] | None = None) -> dict[str, float]:
        """Fold the window into D and I (motions without episodes keep theirs); returns scalars to log.
        `reduce` sums a tensor over data-parallel ranks, so every rank folds all ranks' episodes."""
        if reduce is not None:
            window = reduce(torch.stack([self._failures, self._returns, self._episodes]))
            self._failures, self._returns, self._episodes = window[0], window[1], window[2]
        seen = self._episodes > 0
        count = self._episodes.clamp(min=1)
        failure, mean_return = self._failures / count, self._returns / count
        self.difficulty = torch.where(seen, ema(self.difficulty, failure, self.cfg.failure_ema_decay), self.difficulty)
        has_previous = seen & ~torch.isnan(self.last_return)
        delta = torch.where(has_previous, mean_return - self.last_return, torch.zeros_like(mean_return))
        self.improvement = torch.where(has_previous, ema(self.improvement, delta, self.cfg.return_ema_decay),
                                       self.improvement)
        self.last_return = torch.where(seen, mean_return, self.last_return)
        self.updates += 1
        self._clear_window()
        p = self.probabilities()
        return {"Sampling/difficulty_mean": float(self.difficulty.mean()),
                "Sampling/improvement_mean": float(self.improvement.mean()),
                "Sampling/max_probability": float(p.max())}

    def probabilities(self) -> Tensor:
        return motion_probabilities(self.difficulty, self.improvement, self.group_of, self.num_groups, self.cfg)

    def state_dict(self) -> dict:
        return {"difficulty": self.difficulty.clone(), "improvement": self.improvement.clone(),
                "last_return": self.last_return.clone(), "updates": self.updates}

    def load_state_dict(self, state: dict) -> None:
        self.difficulty, self.improvement = state["difficulty"].clone(), state["improvement"].clone()
        self.last_return, self.updates = state["last_return"].clone(), int(state["updates"])

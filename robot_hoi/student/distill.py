"""Distillation schedule and losses (InterMimic Alg. 1; ComplexMimic Eq. 3-4), as small pure functions."""

from __future__ import annotations

import torch
from torch import Tensor

from robot_hoi.rl.ppo import gaussian_kl
from robot_hoi.student.config import DistillConfig


def student_probability(iteration: int, beta: int) -> float:
    """Alg. 1 line 7: the student's own action is executed when u <= t / beta (u ~ U(0, 1)), i.e. with
    probability min(t / beta, 1); beta = 0 lets the student act from the first iteration."""
    return 1.0 if beta <= 0 else min(iteration / beta, 1.0)


def loss_weights(iteration: int, cfg: DistillConfig) -> tuple[float, float]:
    """(weight of L_PPO, weight of the distillation loss).

    schedule (Alg. 1 line 17-18): w = min(t / beta, 1); the actor minimises w * L_PPO + (1 - w) * J.
    fixed (ComplexMimic Eq. 4): lambda_PPO * L_PPO + lambda_KD * L_KD.
    """
    if cfg.weights == "fixed":
        return cfg.lambda_ppo, cfg.lambda_kd
    w = student_probability(iteration, cfg.beta)
    return w, 1.0 - w


def l2_action_loss(student_mean: Tensor, teacher_action: Tensor) -> Tensor:
    """J(psi) = ||a^(S) - a^(T)|| (Alg. 1 line 16): Euclidean norm over action dims, mean over the batch."""
    return torch.linalg.vector_norm(student_mean - teacher_action, dim=-1).mean()


def kl_action_loss(student_mean: Tensor, student_std: Tensor, teacher_mean: Tensor, teacher_std: Tensor) -> Tensor:
    """L_KD = D_KL(pi_theta(.|s) || pi^(T)(.|s)) between diagonal Gaussians (ComplexMimic Eq. 3), summed over
    action dims, mean over the batch."""
    return gaussian_kl(student_mean, student_std, teacher_mean, teacher_std)


def mix_actions(student: Tensor, teacher: Tensor, use_student: Tensor) -> Tensor:
    """The DAgger mixture: per env, the student's action where `use_student`, else the teacher's."""
    return torch.where(use_student[:, None], student, teacher)

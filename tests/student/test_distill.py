"""Alg. 1's schedule and the distillation losses against hand-computed values."""

import math

import pytest
import torch

from robot_hoi.student.config import DistillConfig
from robot_hoi.student.distill import (
    kl_action_loss,
    l2_action_loss,
    loss_weights,
    mix_actions,
    student_probability,
)


def test_dagger_schedule():
    assert [student_probability(t, 100) for t in (0, 25, 50, 100, 250)] == [0.0, 0.25, 0.5, 1.0, 1.0]
    assert student_probability(0, 0) == 1.0  # beta 0: the student acts from the start
    cfg = DistillConfig(beta=4)
    assert [loss_weights(t, cfg) for t in range(6)] == [(0.0, 1.0), (0.25, 0.75), (0.5, 0.5), (0.75, 0.25),
                                                         (1.0, 0.0), (1.0, 0.0)]
    fixed = DistillConfig(weights="fixed", lambda_ppo=0.3, lambda_kd=2.0)
    assert loss_weights(0, fixed) == loss_weights(1000, fixed) == (0.3, 2.0)


def test_l2_and_kl_losses():
    student = torch.tensor([[0.0, 0.0], [3.0, 4.0]])
    assert l2_action_loss(student, torch.zeros(2, 2)).item() == pytest.approx(2.5)  # (0 + 5) / 2
    # KL(N(0, 1) || N(1, 2)) = log 2 + (1 + 1) / 8 - 1/2 per dimension, summed over 2 dims
    kl = kl_action_loss(torch.zeros(1, 2), torch.ones(1, 2), torch.ones(1, 2), 2 * torch.ones(1, 2))
    assert kl.item() == pytest.approx(2 * (math.log(2) + 0.25 - 0.5), rel=1e-6)
    assert kl_action_loss(student, torch.ones(2, 2), student, torch.ones(2, 2)).item() == 0.0


def test_mixture_picks_per_env():
    student, teacher = torch.ones(3, 2), -torch.ones(3, 2)
    mixed = mix_actions(student, teacher, torch.tensor([True, False, True]))
    assert mixed.tolist() == [[1, 1], [-1, -1], [1, 1]]


def test_config_validation():
    from robot_hoi.errors import UserError
    from robot_hoi.student.config import STUDENT_FAST_CONFIG, load_student_config

    with pytest.raises(UserError, match="distill"):
        load_student_config(STUDENT_FAST_CONFIG, overrides=["distill.loss=huber"])
    with pytest.raises(UserError, match="divisible"):
        load_student_config(STUDENT_FAST_CONFIG, overrides=["student.width=30"])

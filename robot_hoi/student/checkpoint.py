"""Student checkpoints: PPO checkpoints (robot_hoi.rl.checkpoint) with policy_kind "student" and the token layout.

Read with torch.load(weights_only=True) like every checkpoint here; nothing is unpickled.
"""

from __future__ import annotations

from pathlib import Path

import torch

from robot_hoi.errors import UserError
from robot_hoi.rl.checkpoint import load_model_state, read_checkpoint
from robot_hoi.student.config import StudentTrainConfig
from robot_hoi.student.model import StudentActorCritic
from robot_hoi.student.runner import POLICY_KIND
from robot_hoi.student.tokens import TokenLayout


def is_student_checkpoint(path: str | Path) -> bool:
    return read_checkpoint(path).get("policy_kind") == POLICY_KIND


def load_student(path: str | Path, device: str | torch.device = "cpu", averaged: bool = True
                 ) -> tuple[StudentActorCritic, StudentTrainConfig, dict]:
    """Rebuild the trained student from its checkpoint alone, in eval mode: (model, config, checkpoint dict). A run
    with a weight average (stability.ema_decay) gives the average, which it evaluated and selected on, unless
    `averaged` is False (the last trained weights)."""
    data = read_checkpoint(path, map_location=device)
    if data.get("policy_kind") != POLICY_KIND:
        raise UserError(f"{path}: not a student checkpoint (policy_kind {data.get('policy_kind', 'teacher')!r})")
    cfg = StudentTrainConfig.from_json(data["config_json"], f"{path} (stored config)")
    info = data.get("student", {})
    if "token_layout" not in info:
        raise UserError(f"{path}: student checkpoint lacks its token layout")
    layout = TokenLayout.from_dict(info["token_layout"])
    dims = data["dims"]
    model = StudentActorCritic(layout, dims["critic_obs"], dims["num_actions"], cfg.student, cfg.model).to(device)
    load_model_state(model, data["ema_model"] if averaged and "ema_model" in data else data["model"], path)
    model.eval()
    return model, cfg, data

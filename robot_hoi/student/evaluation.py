"""Student vs teachers with `robot-hoi eval`'s machinery (success, duration, E_h, E_o from the stand at the clip
start, deterministic actions), on the references each policy tracks."""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor

from robot_hoi.rl.env import concat_groups
from robot_hoi.rl.evaluation import evaluate


class GroupsAsPolicy:
    """Presents the concatenation of `groups` as the "policy" observation, which evaluate() feeds the model."""

    def __init__(self, env, groups: list[str]) -> None:
        self._env = env
        self._groups = list(groups)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._env, name)

    def _remap(self, obs: dict[str, Tensor]) -> dict[str, Tensor]:
        return {**obs, "policy": concat_groups(obs, self._groups)}

    def reset(self) -> dict[str, Tensor]:
        return self._remap(self._env.reset())

    def step(self, actions: Tensor):
        obs, *rest = self._env.step(actions)
        return (self._remap(obs), *rest)


def evaluate_groups(env, model, groups: list[str]) -> dict[str, float]:
    with torch.no_grad():
        return evaluate(GroupsAsPolicy(env, groups), model)


def format_table(rows: dict[str, dict[str, dict[str, float]]]) -> list[str]:
    """rows[policy][clip] -> metrics; plain text lines (the CLI prints them, tests read them)."""
    lines = [f"{'policy':<44} {'clip':<28} {'success':>7} {'interact':>8} {'dur (s)':>8} {'E_h cm':>7} {'E_o cm':>7} "
             f"{'return':>7}"]
    for policy, clips in rows.items():
        for clip, r in clips.items():
            lines.append(f"{policy:<44} {clip[:28]:<28} {r['success_rate']:>7.2f} {r['interaction_success_rate']:>8.2f} "
                         f"{r['duration_s']:>8.2f} "
                         f"{r['E_h_cm']:>7.1f} {r['E_o_cm']:>7.1f} {r['return']:>7.1f}")
    return lines

"""A student env over clips with different objects: one InteractionEnv per object, stepped side by side.

A compiled scene holds one object, so a student of many skills (a tall box lifted, a 5 kg box walked past, a
table dragged) trains on one env per object and sees them as one batch: `ObjectGroupsEnv` concatenates their
observations, rewards and episode records along the env axis, and clip ids run over every group's clips in
order (group 0's clips first). `GroupedTeacher` asks each group's composite teacher for its own rows. The
observation layout must be the same in every group (it is: sizes come from the config, not the object).
"""

from __future__ import annotations

import torch
from torch import Tensor

from robot_hoi.errors import UserError


def split_envs(num_envs: int, clips_per_group: list[int]) -> list[int]:
    """`num_envs` shared out in proportion to each group's clips (largest remainders), at least one per group: a
    clip is drawn about as often as it would be in one env holding every clip."""
    if num_envs < len(clips_per_group):
        raise UserError(f"env.num_envs {num_envs}: a student over {len(clips_per_group)} objects needs at least one "
                        "env per object")
    total = sum(clips_per_group)
    exact = [num_envs * c / total for c in clips_per_group]
    counts = [max(1, int(e)) for e in exact]
    order = sorted(range(len(exact)), key=lambda i: exact[i] - int(exact[i]), reverse=True)
    i = 0
    while sum(counts) < num_envs:
        counts[order[i % len(order)]] += 1
        i += 1
    while sum(counts) > num_envs:  # the minimum of one pushed it over: take from the largest
        counts[counts.index(max(counts))] -= 1
    return counts


class ObjectGroupsEnv:
    """Implements robot_hoi.rl.env.VecEnv over `envs` (one per object)."""

    def __init__(self, envs: list) -> None:
        if not envs:
            raise ValueError("ObjectGroupsEnv needs at least one env")
        first = envs[0]
        for env in envs[1:]:
            if env.obs_dims != first.obs_dims or env.num_actions != first.num_actions:
                raise UserError(f"object groups disagree on the observation layout ({first.obs_dims} vs "
                                f"{env.obs_dims}); one student cannot read both")
        self.envs = envs
        self.num_envs = sum(e.num_envs for e in envs)
        self.num_actions = first.num_actions
        self.device = first.device
        self.dt = first.dt
        self.cfg = first.cfg
        self.action_scale = first.action_scale
        self.max_episode_length = max(e.max_episode_length for e in envs)
        self.obs_dims = dict(first.obs_dims)
        self.start_sampler = None
        self.references = [r for e in envs for r in e.references]
        counts = [len(e.references) for e in envs]
        self.clip_offsets = [sum(counts[:k]) for k in range(len(envs))]
        bounds = [0]
        for e in envs:
            bounds.append(bounds[-1] + e.num_envs)
        self.rows = [slice(bounds[k], bounds[k + 1]) for k in range(len(envs))]

    @property
    def clip_id(self) -> Tensor:
        """Each env's clip, numbered over every group's clips."""
        return torch.cat([e.clip_id + off for e, off in zip(self.envs, self.clip_offsets, strict=True)])

    def action_offset(self) -> Tensor:
        offsets = [e.action_offset() for e in self.envs]
        return torch.cat([o.expand(e.num_envs, -1) for o, e in zip(offsets, self.envs, strict=True)])

    def reset(self) -> dict[str, Tensor]:
        return _cat_dicts([e.reset() for e in self.envs])

    def step(self, actions: Tensor):
        results = [e.step(actions[rows]) for e, rows in zip(self.envs, self.rows, strict=True)]
        obs = _cat_dicts([r[0] for r in results])
        reward, terminated, truncated = (torch.cat([r[i] for r in results]) for i in (1, 2, 3))
        extras = {"episode": self._episodes([r[4] for r in results]),
                  "log": _weighted_logs([r[4] for r in results])}
        if any("final_obs" in r[4] for r in results):  # rows not truncated in a group keep their observation
            extras["final_obs"] = _cat_dicts([r[4].get("final_obs", r[0]) for r in results])
        return obs, reward, terminated, truncated, extras

    def _episodes(self, extras: list[dict]) -> dict[str, Tensor]:
        parts = []
        for ex, offset in zip(extras, self.clip_offsets, strict=True):
            episode = dict(ex.get("episode", {}))
            if "clip_id" in episode:
                episode["clip_id"] = episode["clip_id"] + offset
            parts.append(episode)
        keys = [k for k in parts[0] if all(k in p for p in parts)]
        return {k: torch.cat([p[k] for p in parts]) for k in keys}

    def update_curriculum(self, total_samples: int) -> dict[str, float]:
        logs = [e.update_curriculum(total_samples) for e in self.envs]
        return logs[0]  # one config: every group follows the same schedule

    def curriculum_state(self) -> dict[str, float]:
        return self.envs[0].curriculum_state()

    def close(self) -> None:
        for e in self.envs:
            e.close()


class GroupedTeacher:
    """The composite teacher of each object group, answering for that group's rows (CompositeTeacher.act)."""

    def __init__(self, composites: list) -> None:
        self.composites = composites
        self.members = [m for c in composites for m in c.members]

    def act(self, env) -> tuple[Tensor, Tensor, Tensor]:
        groups = env.envs
        answers = [c.act(e) for c, e in zip(self.composites, groups, strict=True)]
        first_member = [sum(len(c.members) for c in self.composites[:k]) for k in range(len(self.composites))]
        return (torch.cat([a[0] for a in answers]), torch.cat([a[1] for a in answers]),
                torch.cat([a[2] + first for a, first in zip(answers, first_member, strict=True)]))


def _cat_dicts(parts: list[dict[str, Tensor]]) -> dict[str, Tensor]:
    return {k: torch.cat([p[k] for p in parts]) for k in parts[0]}


def _weighted_logs(extras: list[dict]) -> dict[str, Tensor | float]:
    """Each logged mean over the groups that logged it, weighted by the episodes each ended this step."""
    sums: dict[str, Tensor | float] = {}
    weights: dict[str, float] = {}
    for ex in extras:
        log = ex.get("log", {})
        ended = float(len(ex.get("episode", {}).get("success", ()))) or 1.0
        for key, value in log.items():
            sums[key] = sums.get(key, 0.0) + ended * value
            weights[key] = weights.get(key, 0.0) + ended
    return {k: sums[k] / weights[k] for k in sums}

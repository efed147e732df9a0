"""SkillMimic-V2's adaptive trajectory sampling (Sec. 4.5, Eq. 8).

Starting from reference state s_i trains the clip A_i = {s_i, ..., s_T}. Its sampling probability is

    p_i = exp(-lambda_s * r_i) / sum_j exp(-lambda_s * r_j),    r_i = 1 / (T - i) * sum_{t=i}^{T-1} r_t     (8)

with r_i the mean reward per frame achieved from s_i: an episode's return (masked frames excluded) over the frames
it could have tracked, so early terminations count as zero reward for the rest. r_i is an EMA over the episodes
started at i; a start frame never tried keeps r_i = 0, the most likely. Across clips ("skill classes") the same
rule with lambda_c on each clip's mean r picks the clip.
"""

from __future__ import annotations

import torch
from torch import Tensor


def ats_probabilities(mean_reward: Tensor, strength: float) -> Tensor:
    """Eq. 8: softmax(-lambda_s * r) over the candidate start frames."""
    return torch.softmax(-strength * mean_reward, dim=0)


def trackable_frames(start_frame: Tensor, clip_end: Tensor, max_episode_length: int, hold: Tensor) -> Tensor:
    """T - i of Eq. 8 for episodes from `start_frame`: the reference frames left, capped by the episode length
    minus the frames spent holding (masked)."""
    left = clip_end - start_frame
    return torch.minimum(left, max_episode_length - hold).clamp(min=1)


class AdaptiveTrajectorySampler:
    def __init__(self, clip_start: Tensor, clip_end: Tensor, max_episode_length: int, frame_lambda: float,
                 class_lambda: float, decay: float) -> None:
        self.clip_start, self.clip_end = clip_start.long().cpu(), clip_end.long().cpu()  # a host-side table
        self.max_episode_length = max_episode_length
        self.frame_lambda, self.class_lambda, self.decay = frame_lambda, class_lambda, decay
        total = int(clip_end[-1]) + 1
        self.mean_reward = torch.zeros(total)
        self.visits = torch.zeros(total, dtype=torch.long)

    def starts(self, clip: int) -> Tensor:
        """Candidate start frames of a clip (all but its last frame, which ends an episode at once)."""
        start, end = int(self.clip_start[clip]), int(self.clip_end[clip])
        return torch.arange(start, max(end, start + 1))

    def frame_probabilities(self, clip: int) -> Tensor:
        return ats_probabilities(self.mean_reward[self.starts(clip)], self.frame_lambda)

    def clip_probabilities(self) -> Tensor:
        means = torch.stack([self.mean_reward[self.starts(c)].mean() for c in range(len(self.clip_start))])
        return ats_probabilities(means, self.class_lambda)

    def sample_frames(self, clips: Tensor, generator: torch.Generator | None = None) -> Tensor:
        frames = torch.empty(clips.numel(), dtype=torch.long)
        for clip in clips.unique().tolist():
            rows = (clips == clip).nonzero().flatten()
            picks = torch.multinomial(self.frame_probabilities(clip), rows.numel(), replacement=True,
                                      generator=generator)
            frames[rows] = self.starts(clip)[picks]
        return frames

    def record(self, frames: Tensor, values: Tensor) -> None:
        """Fold per-episode mean rewards into r_i of their start frames (the first visit sets it)."""
        for frame, value in zip(frames.tolist(), values.tolist(), strict=True):
            old = self.mean_reward[frame]
            self.mean_reward[frame] = value if self.visits[frame] == 0 else self.decay * old + (1 - self.decay) * value
            self.visits[frame] += 1

    def observe(self, batch) -> None:
        """student_env.EpisodeBatch listener: episodes the STF sampler started from an ATS-chosen frame."""
        start = batch.start
        if "centroid" not in start:
            return
        rows = (start["custom"] & (start["centroid"] >= 0)).nonzero().flatten()
        if rows.numel() == 0:
            return
        frames = trackable_frames(start["start_frame"][rows], self.clip_end[batch.clip[rows]],
                                  self.max_episode_length, start["hold"][rows])
        self.record(start["centroid"][rows], batch.ret[rows] / frames)

    def state_dict(self) -> dict:
        return {"mean_reward": self.mean_reward.clone(), "visits": self.visits.clone()}

    def load_state_dict(self, state: dict) -> None:
        self.mean_reward, self.visits = state["mean_reward"].clone(), state["visits"].clone()

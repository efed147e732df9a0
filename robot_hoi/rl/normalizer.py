"""Running mean/std observation normaliser.

A plain nn.Module whose statistics are buffers, so `torch.onnx.export` bakes them into the policy graph and the
robot runtime feeds raw observations. Statistics change only through `update()` and only in training mode:
`module.eval()` freezes them.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn


class RunningNormalizer(nn.Module):
    """y = clamp((x - mean) / sqrt(var + eps), -clip, clip), with mean/var over every sample seen by update()."""

    def __init__(self, dim: int, clip: float = 5.0, eps: float = 1e-5) -> None:
        super().__init__()
        self.dim = dim
        self.clip = float(clip)
        self.eps = float(eps)
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        # float64: a float32 count stops growing past 2**24 samples, a few iterations at 8192 envs.
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))

    def forward(self, x: Tensor) -> Tensor:
        std = torch.sqrt(self.var + self.eps)
        return torch.clamp((x - self.mean) / std, -self.clip, self.clip)

    @torch.no_grad()
    def update(self, x: Tensor) -> None:
        """Fold a batch (..., dim) into the statistics (Chan et al. parallel mean/variance); no-op in eval mode."""
        if not self.training:
            return
        batch = x.reshape(-1, self.dim).to(torch.float64)
        n = batch.shape[0]
        if n == 0:
            return
        batch_mean = batch.mean(dim=0)
        batch_var = batch.var(dim=0, unbiased=False)
        total = self.count + n
        old_mean = self.mean.to(torch.float64)
        delta = batch_mean - old_mean
        new_mean = old_mean + delta * (n / total)
        # Combine sums of squared deviations; the first batch replaces the initial var=1 placeholder.
        m2 = self.var.to(torch.float64) * self.count + batch_var * n + delta.square() * self.count * n / total
        self.mean.copy_(new_mean.to(self.mean.dtype))
        self.var.copy_((m2 / total).to(self.var.dtype))
        self.count.copy_(total)

    def extra_repr(self) -> str:
        return f"dim={self.dim}, clip={self.clip}"

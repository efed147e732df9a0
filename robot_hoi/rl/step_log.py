"""Per-step values of a rollout kept on the device, read back to the host once per iteration."""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor


class StepLog:
    """Log values summed on the device: floats, 0-d tensors, or (k,) tensors whose NaN rows carry no value (e.g. a
    metric of the envs whose episode ended this step). `to_host` averages each name over the values it got, in one
    device-to-host transfer together with the given ragged tensors (their NaN entries dropped)."""

    def __init__(self, device: torch.device | str) -> None:
        self.device = torch.device(device)
        self.sums: dict[str, Tensor] = {}
        self.counts: dict[str, Tensor] = {}

    def add(self, name: str, value: Any) -> None:
        v = torch.as_tensor(value).detach().to(self.device, torch.float32).reshape(-1)
        valid = ~torch.isnan(v)
        total, count = torch.where(valid, v, 0.0).sum(), valid.sum()
        if name in self.sums:
            total, count = total + self.sums[name], count + self.counts[name]
        self.sums[name], self.counts[name] = total, count

    def to_host(self, *ragged: Tensor) -> tuple:
        """(means by name, then each of `ragged` as a list of its non-NaN values)."""
        names = list(self.sums)
        parts = [torch.stack([self.sums[n] for n in names] + [self.counts[n].float() for n in names])] if names else []
        parts += [r.to(self.device, torch.float32).reshape(-1) for r in ragged]
        host = torch.cat(parts).cpu() if parts else torch.zeros(0)
        k = len(names)
        means = {n: float(host[i] / host[k + i]) for i, n in enumerate(names) if host[k + i] > 0}
        out, offset = [means], 2 * k
        for r in ragged:
            values = host[offset:offset + r.numel()]
            out.append(values[~torch.isnan(values)].tolist())
            offset += r.numel()
        return tuple(out)

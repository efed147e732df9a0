"""Data-parallel student training with torch.distributed: what each rank shares with the others.

Every rank runs its own envs (seed + rank) and rollouts; the ranks stay one model by
  - gradients: after each minibatch's backward, one all-reduce of all gradients flattened into a single buffer,
    averaged (PPO.gradient_hook), before clipping, so every rank clips and steps the same gradient;
  - observation normalisers: each rollout step folds the moments of every rank's batch (one all-reduce of
    count, sum and squared deviations), so the statistics equal one normaliser that saw all ranks' samples;
  - the stopping decision: the budget is spent when the furthest rank says so (samples count all ranks);
  - the start: rank 0's parameters and buffers are broadcast once the model is built (and after a resume).
Rank 0 alone logs and writes checkpoints (the runner's log_dir is None elsewhere).

Why not DistributedDataParallel: DDP synchronises gradients through hooks armed by the wrapped module's forward(),
but PPO calls the networks through ActorCritic's methods (distribution_normalized, value_normalized), steps two
optimisers with clipping per network, and the learnable log-std belongs to neither network. Wrapping would mean
restructuring PPO; one flattened all-reduce per minibatch is what DDP's bucketed all-reduce computes (the mean of
the ranks' gradients), with one collective instead of several buckets.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import torch
import torch.distributed as dist
from torch import Tensor

from robot_hoi.rl.budget import Budget
from robot_hoi.rl.normalizer import RunningNormalizer


@dataclass(frozen=True)
class Rank:
    """This process's place in the group (world_size 1: a single process, nothing is communicated)."""

    rank: int = 0
    world_size: int = 1
    device: str = "cpu"

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.world_size > 1

    def wait_for_all(self) -> None:
        """Return once every rank is here (after its last collective: the group may then be torn down)."""
        if self.distributed:
            dist.barrier()


def default_nproc() -> int:
    """The number of CUDA devices when there are several, else 1."""
    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    return count if count > 1 else 1


def backend_for(device: str) -> str:
    return "nccl" if str(device).startswith("cuda") else "gloo"


def all_reduce_sum(tensor: Tensor) -> Tensor:
    dist.all_reduce(tensor, op=dist.ReduceOp.SUM)
    return tensor


def sum_over_ranks(device: str):
    """tensor -> its sum over the ranks, communicated on `device` (NCCL reduces CUDA tensors only)."""
    def reduce(tensor: Tensor) -> Tensor:
        return all_reduce_sum(tensor.to(device)).to(tensor.device)

    return reduce


class GradientAverage:
    """PPO.gradient_hook: the mean of every rank's gradients, in one all-reduce of a flat buffer. A parameter
    without a gradient on this rank contributes zeros, so every rank reduces the same layout."""

    def __init__(self, world_size: int) -> None:
        self.world_size = world_size

    @torch.no_grad()
    def __call__(self, params: list[Tensor]) -> None:
        grads = [p.grad if p.grad is not None else torch.zeros_like(p) for p in params]
        flat = torch.cat([g.reshape(-1) for g in grads])
        all_reduce_sum(flat).div_(self.world_size)
        offset = 0
        for p in params:
            n = p.numel()
            p.grad = flat[offset:offset + n].view_as(p).clone()
            offset += n


class SyncedNormalizer(RunningNormalizer):
    """A RunningNormalizer whose every update folds the batches of all ranks (Chan et al.'s merge of the global
    batch, its moments computed around the shared running mean for accuracy)."""

    @classmethod
    def replacing(cls, normalizer: RunningNormalizer) -> SyncedNormalizer:
        synced = cls(normalizer.dim, clip=normalizer.clip, eps=normalizer.eps).to(normalizer.mean.device)
        synced.load_state_dict(normalizer.state_dict())
        synced.train(normalizer.training)
        return synced

    @torch.no_grad()
    def update(self, x: Tensor) -> None:
        if not self.training:
            return
        batch = x.reshape(-1, self.dim).to(torch.float64)
        shift = self.mean.to(torch.float64)
        centred = batch - shift
        moments = torch.cat([torch.tensor([batch.shape[0]], dtype=torch.float64, device=batch.device),
                             centred.sum(0), centred.square().sum(0)])
        all_reduce_sum(moments)
        n = moments[0]
        if n == 0:
            return
        shifted_mean = moments[1:1 + self.dim] / n
        batch_var = (moments[1 + self.dim:] / n - shifted_mean.square()).clamp(min=0.0)
        total = self.count + n
        delta = shifted_mean  # batch mean - running mean
        new_mean = shift + delta * (n / total)
        m2 = self.var.to(torch.float64) * self.count + batch_var * n + delta.square() * self.count * n / total
        self.mean.copy_(new_mean.to(self.mean.dtype))
        self.var.copy_((m2 / total).to(self.var.dtype))
        self.count.copy_(total)


class SharedBudget:
    """A Budget every rank stops on at the same iteration: samples count all ranks' envs, and the fraction spent
    is the largest over the ranks (wall clocks differ a little)."""

    def __init__(self, budget: Budget, world_size: int, device: str) -> None:
        self.budget = replace(budget)
        self.world_size = world_size
        self.device = device

    def describe(self) -> str:
        return f"{self.budget.describe()} over {self.world_size} ranks"

    def fraction_done(self, elapsed_s: float, samples: int, iterations: int) -> float:
        return self.budget.fraction_done(elapsed_s, samples * self.world_size, iterations)

    def exhausted(self, elapsed_s: float, samples: int, iterations: int) -> bool:
        fraction = torch.tensor([self.fraction_done(elapsed_s, samples, iterations)], dtype=torch.float64,
                                device=self.device)
        dist.all_reduce(fraction, op=dist.ReduceOp.MAX)
        return float(fraction) >= 1.0


@torch.no_grad()
def broadcast_state(module: torch.nn.Module, src: int = 0) -> None:
    """Every parameter and buffer of `module` from rank `src`."""
    for tensor in [*module.parameters(), *module.buffers()]:
        dist.broadcast(tensor.data, src)


def state_checksum(module: torch.nn.Module) -> str:
    """sha256 of every entry of the state dict (names, dtypes and bytes): equal on ranks holding the same model."""
    digest = hashlib.sha256()
    for name, tensor in module.state_dict().items():
        digest.update(name.encode())
        digest.update(str(tensor.dtype).encode())
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    return digest.hexdigest()

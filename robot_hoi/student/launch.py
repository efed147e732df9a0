"""`robot-hoi train student`: the student trained in this process, or with `--nproc N` in N processes on this
machine, one data-parallel student.

This process first does once what every rank would otherwise repeat or race on: the ComplexMimic experts, the
distilled references, the SkillMimic-V2 history encoder and task.json (all cached in the run folder). It then
spawns N workers (torch.multiprocessing, start method spawn). Worker r joins the process group (nccl on CUDA,
gloo on CPU; rendezvous through a file), trains on cuda:r or the CPU with env seed + r, prints only as rank 0,
and reports its sample count, parameter checksum and the checkpoints it saved. Rank 0 alone logs, checkpoints
and evaluates. The ranks' checksums must agree: the launcher refuses to report success otherwise.
"""

from __future__ import annotations

import argparse
import faulthandler
import gc
import os
import sys
import tempfile
import traceback
from pathlib import Path

import torch
import torch.distributed as dist
import torch.multiprocessing as mp

from robot_hoi.errors import UserError
from robot_hoi.student.distributed import Rank, backend_for, default_nproc
from robot_hoi.student.pipeline import prepare_run, student_environment, train


def run(args: argparse.Namespace) -> int:
    """`robot-hoi train student`: `pipeline.train` in this process, or in `resolve_nproc(args)` spawned ranks."""
    torch.set_num_threads(max(getattr(args, "torch_threads", 1), 1))
    nproc = resolve_nproc(args)
    if nproc > 1:
        train_distributed(args, nproc)
    else:
        train(args)
    return 0


def resolve_nproc(args: argparse.Namespace) -> int:
    """--nproc, or by default the number of CUDA devices when training on CUDA with more than one, else 1."""
    device = str(getattr(args, "device", "cpu"))
    nproc = getattr(args, "nproc", None)
    if nproc is None:
        return default_nproc() if device.startswith("cuda") else 1
    if nproc < 1:
        raise UserError(f"--nproc must be at least 1, got {nproc}")
    if nproc > 1 and device.startswith("cuda"):
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if nproc > count:
            raise UserError(f"--nproc {nproc} with --device {device}: this machine has {count} CUDA device(s), "
                            "one per process")
    return nproc


def rank_device(device: str, rank: int) -> str:
    if str(device) == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    return f"cuda:{rank}" if str(device).startswith("cuda") else "cpu"


def prepare_caches(args: argparse.Namespace) -> None:
    """Everything the ranks load instead of making: experts, distilled references, history encoder, task.json."""
    setup, _ = prepare_run(args)
    student_environment(setup, write=True)


def train_distributed(args: argparse.Namespace, nproc: int) -> list[dict]:
    """Train with `nproc` spawned ranks; returns their reports (ordered by rank)."""
    prepare_caches(args)
    context = mp.get_context("spawn")
    queue = context.SimpleQueue()
    with tempfile.TemporaryDirectory(prefix="robot-hoi-dist-") as tmp:
        rendezvous = Path(tmp) / "rendezvous"
        print(f"[student] {nproc} processes, backend {backend_for(rank_device(args.device, 0))}")
        try:
            mp.spawn(_worker, args=(nproc, str(rendezvous), args, queue), nprocs=nproc, join=True)
        except Exception as exc:  # a rank failed (the others were stopped): report its own error
            failure = _first_failure(queue)
            if failure is None:
                raise RuntimeError(f"distributed student training failed: {exc}") from None
            if failure["user_error"]:
                raise UserError(f"rank {failure['rank']}: {failure['error']}") from None
            raise RuntimeError(f"rank {failure['rank']} failed:\n{failure['traceback']}") from None
        reports = sorted((r for r in _drain(queue) if "error" not in r), key=lambda r: r["rank"])
    if len(reports) != nproc:
        raise RuntimeError(f"distributed student training: {len(reports)} of {nproc} ranks reported")
    checksums = {r["checksum"] for r in reports}
    for r in reports:
        print(f"[student] rank {r['rank']}: {r['samples']:,} samples, parameters {r['checksum'][:12]}, "
              f"{len(r['checkpoints'])} checkpoint(s) written")
    if len(checksums) != 1:
        raise RuntimeError("the ranks ended with different parameters; data-parallel training diverged")
    print(f"[student] parameters identical on all {nproc} ranks; {reports[0]['total_samples']:,} samples in total")
    return reports


def _worker(rank: int, world_size: int, rendezvous: str, args: argparse.Namespace, queue) -> None:
    faulthandler.enable()  # a crash in native code (gloo, nccl, MuJoCo) shows where it happened
    torch.set_num_threads(max(getattr(args, "torch_threads", 1), 1))
    device = rank_device(args.device, rank)
    if rank != 0:  # rank 0 speaks for the group
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - for the life of this process
    try:
        if device.startswith("cuda"):
            torch.cuda.set_device(device)
        dist.init_process_group(backend_for(device), init_method=f"file://{rendezvous}", rank=rank,
                                world_size=world_size)
        try:
            queue.put(train(args, Rank(rank, world_size, device)))
        finally:
            dist.destroy_process_group()
            # objects in reference cycles (runner <-> PPO hooks) hold physics thread pools: free them now, not
            # during interpreter shutdown, where a pool's threads can outlive what they need (std::terminate)
            gc.collect()
    except BaseException as exc:
        queue.put({"rank": rank, "error": str(exc), "user_error": bool(getattr(exc, "user_error", False)),
                   "traceback": traceback.format_exc()[-4000:]})  # small: a full pipe would block the exit
        raise


def _drain(queue) -> list[dict]:
    items = []
    while not queue.empty():
        items.append(queue.get())
    return items


def _first_failure(queue) -> dict | None:
    failures = [r for r in _drain(queue) if "error" in r]
    return min(failures, key=lambda r: r["rank"]) if failures else None

"""Run many episodes in parallel: one process per core, one MuJoCo (and one ONNX session) per process.

Processes are started with the "spawn" method (a fresh interpreter: no MuJoCo, onnxruntime or thread state
copied by fork) and import only numpy, mujoco, onnxruntime, deploy and sim2sim. An episode that raises is
reported as an error record with its traceback instead of ending the whole run.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable

from sim2sim.episode import EpisodeJob, run_episode


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def run_one(job: EpisodeJob) -> dict:
    try:
        return run_episode(job)
    except Exception as exc:  # reported in the results; the run goes on with the other episodes
        return {"policy": job.policy_label, "clip": job.target.name, "perturbation": job.perturbation.name,
                "episode": job.episode, "seed": job.seed, "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc()}


def _init_worker() -> None:
    logging.basicConfig(level=logging.ERROR)
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def run_jobs(jobs: list[EpisodeJob], workers: int, progress: Callable[[dict], None] | None = None) -> tuple[list[dict], dict]:
    """Results in job order, plus the run's timing (wall, worker CPU seconds, processes)."""
    wall0 = time.perf_counter()
    workers = max(1, min(workers, len(jobs)))
    results: list[dict | None] = [None] * len(jobs)
    if workers == 1:
        # the runtime logs every fault and overrun as a warning; the report has them, so keep the terminal quiet
        deploy_log = logging.getLogger("deploy")
        level = deploy_log.level
        deploy_log.setLevel(logging.ERROR)
        try:
            for i, job in enumerate(jobs):
                results[i] = run_one(job)
                if progress:
                    progress(results[i])
        finally:
            deploy_log.setLevel(level)
    else:
        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(workers, initializer=_init_worker) as pool:
            for i, result in pool.imap_unordered(_indexed, list(enumerate(jobs)), chunksize=1):
                results[i] = result
                if progress:
                    progress(result)
    wall = time.perf_counter() - wall0
    done = [r for r in results if r is not None]
    return done, run_timing(done, wall, workers)


def run_timing(results: list[dict], wall: float, workers: int) -> dict:
    """Speed of a run. Per core: simulated time over the wall time of the processes (start-up included);
    per episode: simulated time over each episode's own wall time; per CPU second: over the CPU time the
    episodes used (what one core delivers when nothing else shares it)."""
    timed = [r["timing"] for r in results if "timing" in r]
    sim_s = sum(t["sim_s"] for t in timed)
    cpu_s = sum(t["episode_cpu_s"] for t in timed)
    episode_wall = sum(t["episode_wall_s"] for t in timed)
    return {
        "workers": workers,
        "wall_s": wall,
        "simulated_s": sim_s,
        "episode_cpu_s": cpu_s,
        "realtime_factor_total": sim_s / wall if wall > 0 else None,
        "realtime_factor_per_core": sim_s / wall / workers if wall > 0 else None,
        "realtime_factor_per_episode": sim_s / episode_wall if episode_wall > 0 else None,
        "realtime_factor_per_cpu_second": sim_s / cpu_s if cpu_s > 0 else None,
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


def _indexed(item: tuple[int, EpisodeJob]) -> tuple[int, dict]:
    index, job = item
    return index, run_one(job)

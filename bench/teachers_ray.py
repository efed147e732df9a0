"""Teachers trained per hour: `robot-hoi train` sequentially vs `--cluster ray` on a local Ray instance.

Writes --teachers synthetic clips (lift-carry and push, distinct seeds), then trains one teacher per clip
(`--group clip`) with a fixed budget of --iterations PPO iterations each (plus the eval.json of each teacher),
first one after another in this process (each teacher's physics pool uses every core), then as Ray tasks with one
CPU each on a local Ray instance with one CPU per core (Ray's start counts: it is part of what a user waits
for). Prints both wall times and teachers/hour and ends with one line:

    teachers_ray_speedup: <sequential wall / Ray wall>

Ideal: about the core count (teachers are independent). Less in practice: the sequential teacher's physics
already runs on every core (only the PPO update and observations are serial), and short budgets lose some of it
to Ray's start and the workers' imports. Example: python bench/teachers_ray.py --teachers 4 --iterations 20
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path


def write_clips(folder: Path, count: int) -> None:
    from robot_hoi.data.synth import KINDS, default_clip

    folder.mkdir(parents=True)
    for i in range(count):
        default_clip(KINDS[i % len(KINDS)], seed=i // len(KINDS)).save(folder / f"clip_{i:02d}.npz")


def timed_train(clips: Path, out: Path, args, *extra: str) -> float:
    from robot_hoi.cli import main

    argv = ["train", "--data", str(clips), "--group", "clip", "--out", str(out),
            "--budget", f"{args.teachers * args.iterations}it",  # split evenly: --iterations per teacher
            "--set", f"env.num_envs={args.envs}", "--set", "runner.progress=false",
            "--set", "runner.tensorboard=false", "--eval-episodes", "2", *extra]
    start = time.perf_counter()
    code = main(argv)
    wall = time.perf_counter() - start
    if code != 0:
        raise SystemExit(f"robot-hoi train {' '.join(extra)} exited {code}")
    report = json.loads((out / "teachers.json").read_text())
    assert len(report["teachers"]) == args.teachers, report["failures"]
    assert all(t["iteration"] == args.iterations for t in report["teachers"].values())
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--teachers", type=int, default=os.cpu_count() or 1, help="groups (default: core count)")
    parser.add_argument("--iterations", type=int, default=20, help="PPO iterations per teacher")
    parser.add_argument("--envs", type=int, default=64, help="envs per teacher")
    args = parser.parse_args()
    import ray

    with tempfile.TemporaryDirectory(prefix="teachers_ray_") as tmp:
        tmp = Path(tmp)
        write_clips(tmp / "clips", args.teachers)
        sequential = timed_train(tmp / "clips", tmp / "sequential", args)
        start = time.perf_counter()  # Ray's start counts, as it does for a user
        ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False)
        try:
            timed_train(tmp / "clips", tmp / "ray", args, "--cluster", "ray")
            on_ray = time.perf_counter() - start
        finally:
            ray.shutdown()

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.2f}; {args.teachers} teachers x {args.iterations} iterations x {args.envs} envs")
    for name, wall in (("sequential", sequential), ("ray (local)", on_ray)):
        print(f"{name:12s} wall {wall:7.1f} s  {args.teachers * 3600 / wall:8.1f} teachers/hour")
    print(f"teachers_ray_speedup: {sequential / on_ray:.2f}")


if __name__ == "__main__":
    main()

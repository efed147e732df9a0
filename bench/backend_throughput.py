"""Interaction env throughput per physics backend and device, in one run.

Times the full env step (physics + observations + rewards + terminations + resets) on the CPU backend
(`mujoco.rollout` thread pool) and on the MuJoCo Warp backend on every device warp has here (its CPU device
always; `cuda:0` when a GPU is present, with thousands of envs). Medians over repeats, after one warm-up
step per env (kernel compilation and CUDA graph capture are not timed). Ends with
`warp_vs_cpu_env_steps_ratio: <best warp rate / cpu rate>`.

    python bench/backend_throughput.py [--cpu-envs 64] [--warp-cpu-envs 16] [--cuda-envs 4096] [--repeats 3]

Warp's CPU device runs its kernels serially and is there for portability and tests, not speed: expect it
well below the CPU backend. The GPU figure is the one that matters for training.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import torch


def measure(backend: str, device: str | None, num_envs: int, steps: int, repeats: int, clip: str,
            nthread: int) -> tuple[float, float]:
    """Median control steps/s of the env over `repeats` runs of `steps` steps; returns (rate, build seconds)."""
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg

    embodiment = load_embodiment("g1_inspire")
    cfg = InteractionEnvCfg(num_envs=num_envs, nthread=nthread, backend=backend, sim_device=device)
    t0 = time.perf_counter()
    env = factory.make_env([factory.load_source(clip)], cfg, embodiment)
    actions = torch.zeros(num_envs, env.num_actions, device=env.device)
    env.reset()
    env.step(actions)  # warm-up: kernels compiled, graphs captured
    sync = torch.cuda.synchronize if env.device.type == "cuda" else (lambda: None)
    sync()
    build_s = time.perf_counter() - t0
    rates = []
    for _ in range(repeats):
        env.reset()
        sync()
        t0 = time.perf_counter()
        for _ in range(steps):
            env.step(actions + 0.05 * torch.randn_like(actions))
        sync()
        rates.append(num_envs * steps / (time.perf_counter() - t0))
    return statistics.median(rates), build_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cpu-envs", type=int, default=64)
    parser.add_argument("--cpu-steps", type=int, default=60)
    parser.add_argument("--warp-cpu-envs", type=int, default=16)
    parser.add_argument("--warp-cpu-steps", type=int, default=10)
    parser.add_argument("--cuda-envs", type=int, default=4096)
    parser.add_argument("--cuda-steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--clip", default="embedded:lift_carry")
    args = parser.parse_args()
    torch.set_num_threads(1)  # the physics pool owns the cores

    from robot_hoi.embodiment import load_embodiment

    decimation = load_embodiment("g1_inspire").decimation
    runs = [("cpu", None, args.cpu_envs, args.cpu_steps)]
    try:
        import warp as wp

        wp.config.quiet = True
        wp.config.log_level = wp.LOG_WARNING
        runs.append(("warp", "cpu", args.warp_cpu_envs, args.warp_cpu_steps))
        if wp.is_cuda_available() and torch.cuda.is_available():
            runs.append(("warp", "cuda:0", args.cuda_envs, args.cuda_steps))
    except ImportError:
        print("mujoco-warp is not installed (pip install -e '.[warp]'): CPU backend only")

    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "none"
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, GPU {gpu}; "
          f"{args.threads} physics threads (cpu backend), decimation {decimation}, clip {args.clip}")
    rates = {}
    for backend, device, num_envs, steps in runs:
        rate, build_s = measure(backend, device, num_envs, steps, args.repeats, args.clip, args.threads)
        label = backend if device is None else f"{backend}[{device}]"
        rates[label] = rate
        print(f"{label:16s} {num_envs:6d} envs  {rate:10.0f} control steps/s  {rate * decimation:11.0f} "
              f"physics steps/s  (build + warm-up {build_s:5.1f} s)")
    best_warp = max((r for k, r in rates.items() if k.startswith("warp")), default=float("nan"))
    print(f"warp_vs_cpu_env_steps_ratio: {best_warp / rates['cpu']:.3f}")


if __name__ == "__main__":
    main()

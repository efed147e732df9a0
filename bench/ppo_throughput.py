"""PPO update throughput for the InterMimic teacher network (actor and critic MLPs [1024, 1024, 512]).

Fills a rollout of --samples transitions (obs --obs-dim, actions --actions) through the real PPO.act /
process_env_step path, then times PPO.update (Table C settings: 6 mini-epochs, separate Adam optimisers,
action-bound loss). Prints each run and finishes with one line:

    ppo_update_samples_per_s: <rollout samples consumed per second of update, median over runs>

Each sample is visited num_epochs times, so gradient samples/s = that value x num_epochs.
Example: python bench/ppo_throughput.py --device cpu --runs 5
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from robot_hoi.rl.config import ActorCriticConfig, PPOConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.rl.ppo import PPO


def fill_rollout(alg: PPO, num_envs: int, obs_dim: int) -> None:
    storage = alg.storage
    zeros = torch.zeros(num_envs, dtype=torch.bool, device=alg.device)
    for _ in range(storage.horizon):
        obs = torch.randn(num_envs, obs_dim, device=alg.device)
        alg.act(obs, obs)
        alg.process_env_step(torch.randn(num_envs, device=alg.device), zeros, zeros)
    alg.compute_returns(torch.randn(num_envs, obs_dim, device=alg.device))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--samples", type=int, default=4096, help="rollout size (horizon 32 x samples/32 envs)"
    )
    parser.add_argument("--obs-dim", type=int, default=700)
    parser.add_argument("--actions", type=int, default=41)
    parser.add_argument("--num-minibatches", type=int, default=1)
    parser.add_argument("--epochs", type=int, default=6)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument(
        "--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)"
    )
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    horizon = 32
    if args.samples % horizon:
        parser.error(f"--samples must be a multiple of the horizon ({horizon})")
    num_envs = args.samples // horizon

    torch.manual_seed(0)
    model = ActorCritic(args.obs_dim, args.obs_dim, args.actions, ActorCriticConfig()).to(device)
    cfg = PPOConfig(
        horizon=horizon, minibatch_size=None, num_minibatches=args.num_minibatches, num_epochs=args.epochs
    )
    alg = PPO(model, cfg, device)
    alg.init_storage(num_envs, args.obs_dim, args.obs_dim, args.actions, {})

    def timed_update() -> float:
        fill_rollout(alg, num_envs, args.obs_dim)
        if device.type == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        alg.update()
        if device.type == "cuda":
            torch.cuda.synchronize()
        return time.perf_counter() - start

    timed_update()  # warm-up (allocator, kernels, Adam state)
    rates = []
    for run in range(args.runs):
        seconds = timed_update()
        rates.append(args.samples / seconds)
        print(
            f"run {run + 1}/{args.runs}: update of {args.samples} samples x {args.epochs} epochs in {seconds:.3f} s"
        )
    print(
        f"device {device}, threads {torch.get_num_threads()}, obs {args.obs_dim}, actions {args.actions}, "
        f"minibatches {args.num_minibatches}, epochs {args.epochs}"
    )
    print(f"ppo_update_samples_per_s: {statistics.median(rates):.1f}")


if __name__ == "__main__":
    main()

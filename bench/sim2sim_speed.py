"""sim2sim speed: simulated seconds per wall second per core, with the whole runtime in the loop.

    python bench/sim2sim_speed.py [--policy P.onnx] [--workers N] [--episodes-per-worker 2] [--seconds S]

Each episode is a full sim2sim episode of the nominal world (MuJoCo at 2 ms with the motor PD at 500 Hz,
deploy's runtime at 30 Hz on the simulated clock, both Inspire hands speaking serial bytes, the mocap tracker),
with early termination switched off so every episode simulates the same length whatever the policy does.
`--workers` processes (default: one per core) run at once. Figures, per episode (world build, hand connection
and the run; not process start-up):
    wall     simulated time / the episode's wall time: what a core delivers here, *including* any share of
             it taken by other work on the machine (the load average is printed);
    CPU      simulated time / the CPU time the episode's process used: what a core delivers when nothing else
             runs on it (on an idle machine wall and CPU agree).
The last line, `sim2sim_realtime_factor_per_core: <value>` (goal: >= 20), is the CPU figure, so that it does
not depend on who else is using the machine; the wall figure is printed above it.
Without --policy the bench exports an untrained deployable policy (robot-hoi export onnx --untrained) and runs
a policy with its contract and reference whose actions are 0 with fixed offsets: the robot holds its default
stand for the whole clip (a flailing untrained policy falls and lies in contact with the floor, which is
neither representative nor repeatable).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def standing_policy(exported: Path) -> Path:
    """A policy file with the exported contract and reference whose targets are always the default pose."""
    import json

    import numpy as np
    import onnx

    from deploy.contract import PolicyContract
    from deploy.devpolicy import onnx_bytes

    contract = PolicyContract.from_onnx(exported)
    metadata = {p.key: p.value for p in onnx.load(str(exported)).metadata_props}
    metadata["action_offset_mode"] = json.dumps("fixed")
    path = exported.with_name("stand.onnx")
    weights = np.zeros((contract.obs_dim, contract.num_actions), np.float32)
    path.write_bytes(onnx_bytes(metadata, weights, np.zeros(contract.num_actions, np.float32)))
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default=None, help="deployable ONNX policy (default: export an untrained one)")
    parser.add_argument("--workers", type=int, default=None, help="parallel processes (default: one per core)")
    parser.add_argument("--episodes-per-worker", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=None, help="simulate only the first seconds of the clip")
    parser.add_argument("--hand-bus", default="serial", choices=("serial", "modbus", "can"))
    parser.add_argument("--hand-link", default=None, choices=("direct", "pty"))
    args = parser.parse_args(argv)

    from deploy.contract import PolicyContract
    from robot_hoi.cli import main as robot_hoi_main
    from sim2sim.episode import EpisodeJob
    from sim2sim.evaluate import machine
    from sim2sim.monitor import Thresholds
    from sim2sim.perturbations import NOMINAL
    from sim2sim.runner import default_workers, run_jobs
    from sim2sim.targets import policy_targets

    with tempfile.TemporaryDirectory() as tmp:
        policy = args.policy
        if policy is None:
            exported = Path(tmp) / "untrained.onnx"
            if robot_hoi_main(["export", "onnx", "--untrained", "-o", str(exported)]) != 0:
                return 1
            policy = str(standing_policy(exported))
        contract = PolicyContract.from_onnx(policy)
        target = policy_targets(contract, None, "g1_inspire", True)[0]
        frames = None if args.seconds is None else int(args.seconds * target.motion.fps)
        never = Thresholds(float("inf"), float("-inf"), float("inf"), float("inf"), 10**9)
        workers = args.workers or default_workers()
        link = args.hand_link or ("pty" if args.hand_bus == "can" else "direct")
        jobs = [EpisodeJob(policy, "bench", target, NOMINAL, ep, ep, thresholds=never, max_frames=frames,
                           hand_transport=args.hand_bus, hand_link=link, keep_traces=False)
                for ep in range(workers * args.episodes_per_worker)]
        info = machine()
        print(f"machine: {info['description']}, python {info['python']}, mujoco {info['mujoco']}, "
              f"load average {os.getloadavg()[0]:.1f} at start")
        print(f"{len(jobs)} episode(s) of {target.name} ({(frames or target.motion.num_frames - 1) / target.motion.fps:.1f} s "
              f"of policy time each) on {workers} process(es); hands: {args.hand_bus} ({link} link)")
        t0 = time.perf_counter()
        results, timing = run_jobs(jobs, workers)
        wall = time.perf_counter() - t0
    bad = [r for r in results if "error" in r]
    if bad:
        print(f"{len(bad)} episode(s) failed: {bad[0]['error']}\n{bad[0]['traceback']}")
        return 1
    per_episode = [r["timing"] for r in results]
    rtf = [t["sim_s"] / t["episode_wall_s"] for t in per_episode]
    cpu_rtf = [t["sim_s"] / t["episode_cpu_s"] for t in per_episode]
    physics_share = [t["physics_wall_s"] / t["run_wall_s"] for t in per_episode]
    ticks_p50 = [t["policy_tick_wall_ms"]["p50"] for t in per_episode]
    ticks_p99 = [t["policy_tick_wall_ms"]["p99"] for t in per_episode]
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    print(f"{'episode':>7} {'sim s':>6} {'wall s':>7} {'cpu s':>6} {'x real':>7} {'physics':>8} {'tick p50':>9}")
    for i, t in enumerate(per_episode):
        print(f"{i:>7} {t['sim_s']:>6.2f} {t['episode_wall_s']:>7.2f} {t['episode_cpu_s']:>6.2f} {rtf[i]:>7.1f} "
              f"{100 * physics_share[i]:>7.0f}% {ticks_p50[i]:>7.2f}ms")
    print(f"load average {os.getloadavg()[0]:.1f} at the end on {info['cores']} core(s)")
    print(f"per episode: {mean(rtf):.1f} x real time per core (wall), {mean(cpu_rtf):.1f} x per CPU second; "
          f"physics {100 * mean(physics_share):.0f}% of the run, policy tick p50 {mean(ticks_p50):.2f} ms, "
          f"p99 {max(ticks_p99):.2f} ms")
    print(f"whole run incl. process start-up: {timing['simulated_s']:.1f} simulated s in {wall:.1f} s wall on "
          f"{workers} process(es) = {timing['simulated_s'] / wall:.1f} x real time in total")
    print(f"sim2sim_realtime_factor_per_core: {mean(cpu_rtf):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

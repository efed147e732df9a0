"""Interaction env throughput vs raw mujoco.rollout on the same compiled model, in one run.

Prints control steps/s and physics steps/s of the full env step (physics + observations + rewards +
terminations + resets) and of bare `mujoco.rollout` stepping the same scene with the same env count and threads,
medians over repeats. Ends with `env_vs_rollout_ratio: <physics-steps ratio>` (goal >= 0.8).

    python bench/env_throughput.py [--envs 64] [--steps 60] [--repeats 5] [--clip embedded:lift_carry]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import mujoco
import numpy as np
import torch
from mujoco import rollout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", type=int, default=64)
    parser.add_argument("--steps", type=int, default=60, help="control steps per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--clip", default="embedded:lift_carry")
    args = parser.parse_args()
    torch.set_num_threads(1)  # the physics pool owns the cores

    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg

    embodiment = load_embodiment("g1_inspire")
    cfg = InteractionEnvCfg(num_envs=args.envs, nthread=args.threads)
    env = factory.make_env([factory.load_source(args.clip)], cfg, embodiment)
    decimation = env.backend.decimation
    actions = torch.zeros(args.envs, env.num_actions)

    env_rates = []
    for _ in range(args.repeats):
        env.reset()
        t0 = time.perf_counter()
        for _ in range(args.steps):
            env.step(actions + 0.05 * torch.randn_like(actions))
        env_rates.append(args.envs * args.steps / (time.perf_counter() - t0))

    # Raw rollout: the same model, env count, threads and per-call physics steps, nothing else.
    model = env.scene.model
    pool = rollout.Rollout(nthread=args.threads)
    datas = [mujoco.MjData(model) for _ in range(args.threads)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS.value
    state0 = env.backend._state.copy()
    ctrl = np.tile(embodiment.default_pos, (args.envs, decimation, 1))
    state_out = np.zeros((args.envs, decimation, mujoco.mj_stateSize(model, spec)))
    sens_out = np.zeros((args.envs, decimation, model.nsensordata))
    models = [model] * args.envs
    raw_rates = []
    for _ in range(args.repeats):
        state = state0.copy()
        t0 = time.perf_counter()
        for _ in range(args.steps):
            pool.rollout(models, datas, state, ctrl, skip_checks=True, nstep=decimation, state=state_out,
                         sensordata=sens_out)
            state[:] = state_out[:, -1]
        raw_rates.append(args.envs * args.steps / (time.perf_counter() - t0))
    pool.close()

    env_ctrl, raw_ctrl = statistics.median(env_rates), statistics.median(raw_rates)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"{args.threads} physics threads, {args.envs} envs, decimation {decimation}")
    print(f"env step:      {env_ctrl:9.0f} control steps/s  {env_ctrl * decimation:9.0f} physics steps/s")
    print(f"raw rollout:   {raw_ctrl:9.0f} control steps/s  {raw_ctrl * decimation:9.0f} physics steps/s")
    print(f"env_vs_rollout_ratio: {env_ctrl / raw_ctrl:.3f}")


if __name__ == "__main__":
    main()

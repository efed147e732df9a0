"""Teacher training throughput vs the raw `mujoco.rollout` ceiling of the same robot, in one run (issue 15).

Training: what `robot-hoi train` runs by default (configs/tasks/interaction.yaml, the fast PPO preset, the embedded
default clip, torch on 1 thread, the runner's own logging into a temporary run folder), --warmup-iterations
first, then --iterations timed. The wall time is split by robot_hoi/utils/timing.py hooks in the env and runner:
physics (env.backend.step), state/rewards/terminations, observations, resets, policy inference (normalisers and
actor/critic forward), storage (transition bookkeeping), PPO update (GAE and epochs), logging (read-backs, scalars,
TensorBoard, progress) and other (the final checkpoint of the call).

Raw ceiling: bare `mujoco.rollout` on the env's own compiled model (robot + floor + the clip's object, same
sensors), the same env count, physics threads and sub-steps per control step, from the env's reset states with the
PD targets of a zero action held, recording states and sensors as the backend does; median over repeats.

Ends with `train_vs_raw_physics: <training env samples/s / raw control steps/s>` (issue 15's goal: >= 0.57).

    python bench/train_throughput.py [--iterations 30] [--num-envs N] [--threads N] [--torch-threads 1]
                                     [--train-set ppo.horizon=24]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
import torch
from mujoco import rollout

# (label, timer names) in print order; "other" is the rest of the wall time
SPLIT = (
    ("physics", ("physics",)),
    ("obs/rewards/terminations", ("state_rewards_terminations", "observations")),
    ("  of which observations", ("observations",)),
    ("resets", ("resets",)),
    ("policy inference", ("policy",)),
    ("rollout storage", ("storage",)),
    ("PPO update", ("update",)),
    ("logging", ("logging",)),
)


def build_training(args, run_dir: Path):
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.rl.config import PRESETS, load_train_config
    from robot_hoi.rl.runner import OnPolicyRunner
    from robot_hoi.sim.device import policy_device, resolve_env_cfg
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.utils.config import load_yaml_dataclass

    overrides = [] if args.num_envs is None else [f"num_envs={args.num_envs}"]
    if args.threads:
        overrides.append(f"nthread={args.threads}")
    if args.backend:
        overrides.append(f"backend={args.backend}")
    env_cfg = resolve_env_cfg(load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG, overrides))
    embodiment = load_embodiment("g1_inspire")
    env_cfg.embodiment = embodiment.name
    train_cfg = load_train_config(PRESETS[args.preset], ["runner.progress=false", *args.train_set])
    clip = factory.load_source(args.clip)
    env = factory.make_env([clip], env_cfg, embodiment, cache=run_dir / "references")
    runner = OnPolicyRunner(env, train_cfg, run_dir, device=policy_device("auto", env.device))
    return env, runner


def raw_rollout_rate(env, threads: int, steps: int, repeats: int) -> float:
    """Control steps/s of bare mujoco.rollout on the env's model from its reset states (see the module doc)."""
    env.reset()
    model = env.scene.model
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS.value
    qpos = env.backend.qpos.detach().cpu().double().numpy()
    qvel = env.backend.qvel.detach().cpu().double().numpy()
    data = mujoco.MjData(model)
    state0 = np.zeros((env.num_envs, mujoco.mj_stateSize(model, spec)))
    for i in range(env.num_envs):
        data.qpos[:], data.qvel[:] = qpos[i], qvel[i]
        mujoco.mj_getState(model, data, state0[i], spec)
    targets = torch.maximum(torch.minimum(env.action_offset().expand(env.num_envs, -1), env.ctrl_high), env.ctrl_low)
    decimation = env.backend.decimation
    ctrl = np.ascontiguousarray(np.repeat(targets.detach().cpu().double().numpy()[:, None], decimation, axis=1))
    return rollout_rate(model, state0, ctrl, threads, steps, repeats)


def rollout_rate(model: mujoco.MjModel, state0: np.ndarray, ctrl: np.ndarray, threads: int, steps: int,
                 repeats: int) -> float:
    """Median control steps/s of `steps` mujoco.rollout calls from the full-physics states `state0` (envs, nstate),
    each of ctrl.shape[1] physics steps with the controls `ctrl` (envs, sub-steps, nu) held, recording states and
    sensors as the CPU backend does."""
    envs, decimation = ctrl.shape[:2]
    state_out = np.zeros((envs, decimation, state0.shape[1]))
    sens_out = np.zeros((envs, decimation, model.nsensordata))
    models = [model] * envs
    datas = [mujoco.MjData(model) for _ in range(threads)]
    rates = []
    with rollout.Rollout(nthread=threads) as pool:
        for _ in range(repeats):
            state = state0.copy()
            t0 = time.perf_counter()
            for _ in range(steps):
                pool.rollout(models, datas, state, ctrl, skip_checks=True, nstep=decimation, state=state_out,
                             sensordata=sens_out)
                state[:] = state_out[:, -1]
            rates.append(envs * steps / (time.perf_counter() - t0))
    return statistics.median(rates)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iterations", type=int, default=30, help="timed PPO iterations (default 30)")
    parser.add_argument("--warmup-iterations", type=int, default=2, help="untimed iterations first (default 2)")
    parser.add_argument("--num-envs", type=int, default=None, help="default: the task config's (what training uses)")
    parser.add_argument("--threads", type=int, default=None,
                        help="physics threads (default: the env's, min(cores, envs)); the raw ceiling uses the same")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch CPU threads (robot-hoi train's default 1)")
    parser.add_argument("--preset", default="fast", choices=["fast", "paper"])
    parser.add_argument("--backend", default=None, choices=["auto", "cpu", "warp"],
                        help="physics backend of the training env (default: the task config's)")
    parser.add_argument("--clip", default="embedded:lift_place")
    parser.add_argument("--train-set", action="append", default=[], metavar="KEY=VALUE",
                        help="override of the training preset, e.g. ppo.horizon=24 (repeatable)")
    parser.add_argument("--raw-steps", type=int, default=48, help="control steps per raw repeat (default 48)")
    parser.add_argument("--raw-repeats", type=int, default=5)
    args = parser.parse_args(argv)
    if args.iterations < 1 or args.warmup_iterations < 0:
        parser.error("--iterations must be >= 1 and --warmup-iterations >= 0")
    torch.set_num_threads(max(args.torch_threads, 1))

    from robot_hoi.rl.budget import Budget
    from robot_hoi.utils.timing import Timers

    with tempfile.TemporaryDirectory(prefix="train_throughput_") as tmp:
        t_setup = time.perf_counter()
        env, runner = build_training(args, Path(tmp))
        setup_s = time.perf_counter() - t_setup
        if args.warmup_iterations:
            runner.learn(Budget(iterations=args.warmup_iterations))
        sync = torch.cuda.synchronize if env.device.type == "cuda" or runner.device.type == "cuda" else None
        timers = Timers(sync=sync)
        env.timers = runner.timers = timers
        t0 = time.perf_counter()
        runner.learn(Budget(iterations=args.iterations))
        wall = time.perf_counter() - t0
        runner.close()

    samples = args.iterations * runner.alg.storage.batch_size
    train_rate = samples / wall
    threads = getattr(env.backend, "nthread", None) or args.threads or min(os.cpu_count() or 1, env.num_envs)
    raw_rate = raw_rollout_rate(env, threads, args.raw_steps, args.raw_repeats)
    decimation = env.backend.decimation

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f} (1 min) at the end; backend {env.cfg.backend} ({env.device}), policy on "
          f"{runner.device}, {threads} physics threads, {torch.get_num_threads()} torch threads")
    print(f"training: {args.preset} preset, {env.num_envs} envs, horizon {runner.cfg.ppo.horizon}, obs "
          f"{dict(env.obs_dims)}, decimation {decimation}; setup {setup_s:.1f} s, {args.warmup_iterations} warm-up "
          f"iterations")
    print(f"training:      {args.iterations} iterations, {samples} samples in {wall:.2f} s = {train_rate:9.0f} "
          f"samples/s")
    print(f"raw rollout:   {raw_rate:9.0f} control steps/s  {raw_rate * decimation:9.0f} physics steps/s "
          f"({args.raw_repeats} x {args.raw_steps} control steps, median)")
    physics = timers.seconds.get("physics", 0.0)
    if physics > 0:
        print(f"physics inside training: {samples / physics:9.0f} control steps/s "
              f"({samples / physics / raw_rate:.2f} of raw)")
    print("wall-time split:")
    accounted = sum(timers.seconds.values())
    for label, names in SPLIT:
        seconds = sum(timers.seconds.get(n, 0.0) for n in names)
        print(f"  {label:26s} {seconds:8.2f} s  {100 * seconds / wall:5.1f} %  {1e6 * seconds / samples:7.1f} us/sample")
    other = wall - accounted
    print(f"  {'other (final checkpoint)':26s} {other:8.2f} s  {100 * other / wall:5.1f} %  "
          f"{1e6 * other / samples:7.1f} us/sample")
    print(f"train_vs_raw_physics: {train_rate / raw_rate:.3f}")


if __name__ == "__main__":
    main()

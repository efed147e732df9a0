"""Physics sub-steps per control step: what each costs and whether it keeps the behaviour (issue 15).

For each sub-step count N (the control rate stays 30 Hz, so the physics dt is 33.3 ms / N) against a fine
reference (--fine, default 14 sub-steps = 2.4 ms):
- cost: bare `mujoco.rollout` control steps/s of the robot + box scene (64 copies, the machine's cores as threads,
  default-pose PD targets held), median of repeats;
- stance: the robot in its default pose under PD alone for 3 s from the stand: final pelvis height and the largest
  pelvis deviation from the fine run at the same control step;
- push: as the stance, with a 0.5 m/s lateral push of the pelvis at 0.5 s: the same figures;
- lift: the hold test of `embedded:lift_place` (zero residual, pelvis held on its reference, object left alone:
  robot_hoi/tasks/interaction/feasibility.py): the frames the replay lasts and how far the box falls below its
  reference while held;
- with --checkpoint: that teacher evaluated from the stand (--episodes) at each N: success, interaction success.

A count is faithful when every trial ends as the fine one does (upright or not), the pelvis stays within 2 cm of the
fine run in the stance and 5 cm after the push, the hold replay lasts within 10 % of the fine one's frames with the
held box within 1 cm of the fine drop, and a checkpoint (if given) loses at most 1/8 of its fine success. Ends with
`cheapest_faithful_substeps: N` (the smallest faithful N; 0 when none is).

    PYTHONPATH=. python bench/substeps.py [--substeps 4 5 7] [--fine 14] [--checkpoint runs/.../model_925.pt]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import mujoco
import numpy as np
import torch
from train_throughput import rollout_rate  # bench/ is on the path when run as a script

CONTROL_HZ = 30.0
STANCE_S, PUSH_AT_S, PUSH_SPEED = 3.0, 0.5, 0.5
UPRIGHT_PELVIS_Z = 0.5


def _scene(substeps: int):
    from robot_hoi.data.objects import box_asset
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.tasks.interaction.scene_setup import InteractionScene

    return InteractionScene(load_embodiment("g1_inspire", [f"decimation={substeps}"]), box_asset((0.4, 0.4, 0.3)))


def _stand_state(scene) -> tuple[np.ndarray, np.ndarray]:
    lay = scene.layout
    qpos = scene.model.qpos0.copy()
    qpos[: lay.robot_nq] = scene.default_robot_qpos()[0].double().numpy()
    qpos[lay.object_qpos:lay.object_qpos + 3] = (3.0, 0.0, 0.15)  # out of the way
    return qpos, np.zeros(scene.model.nv)


def _hold_targets(scene) -> np.ndarray:
    lo, hi = scene.actuator_ctrlrange()
    return np.clip(scene.embodiment.default_pos, lo, hi)


def raw_rate(scene, envs: int, threads: int, steps: int, repeats: int) -> float:
    model, n = scene.model, scene.embodiment.decimation
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS.value
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = _stand_state(scene)
    state0 = np.zeros((envs, mujoco.mj_stateSize(model, spec)))
    mujoco.mj_getState(model, data, state0[0], spec)
    state0[:] = state0[0]
    ctrl = np.ascontiguousarray(np.broadcast_to(_hold_targets(scene), (envs, n, model.nu)))
    return rollout_rate(model, state0, ctrl, threads, steps, repeats)


def pelvis_track(scene, push: bool) -> np.ndarray:
    """(control steps, 3) pelvis positions of the default-pose stand (with the push at 0.5 s)."""
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = _stand_state(scene)
    data.ctrl[:] = _hold_targets(scene)
    mujoco.mj_forward(model, data)
    track = []
    for step in range(int(STANCE_S * CONTROL_HZ)):
        if push and step == int(PUSH_AT_S * CONTROL_HZ):
            data.qvel[1] += PUSH_SPEED
        for _ in range(scene.embodiment.decimation):
            mujoco.mj_step(model, data)
        track.append(data.qpos[0:3].copy())
    return np.array(track)


def lift_hold(substeps: int, clip) -> dict:
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.tasks.interaction.feasibility import physics_gate
    from robot_hoi.utils.config import load_yaml_dataclass

    embodiment = load_embodiment("g1_inspire", [f"decimation={substeps}"])
    return physics_gate(clip, load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG), embodiment)


def checkpoint_eval(substeps: int, checkpoint: str, episodes: int) -> dict:
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.rl.checkpoint import load_policy
    from robot_hoi.rl.evaluation import evaluate, evaluation_settings
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import saved_env_cfg

    checkpoint = Path(checkpoint)
    model, _, _ = load_policy(checkpoint)
    task = factory.read_task(checkpoint)
    env_cfg = saved_env_cfg(task["env"], f"{checkpoint} task")
    evaluation_settings(env_cfg, episodes, 0)
    env_cfg.backend = "cpu"
    embodiment = load_embodiment(env_cfg.embodiment, [f"decimation={substeps}"])
    clip = factory.load_source(task["sources"][0], task.get("clip_options"))
    env = factory.make_env([clip], env_cfg, embodiment, cache=checkpoint.parent / "references")
    return evaluate(env, model)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--substeps", type=int, nargs="+", default=[4, 5, 7])
    parser.add_argument("--fine", type=int, default=14, help="the reference sub-step count (default 14)")
    parser.add_argument("--envs", type=int, default=64)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--raw-steps", type=int, default=48)
    parser.add_argument("--raw-repeats", type=int, default=5)
    parser.add_argument("--checkpoint", default=None, help="a teacher checkpoint to evaluate at each count")
    parser.add_argument("--episodes", type=int, default=16)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)

    from robot_hoi.tasks.interaction import factory

    clip = factory.load_source("embedded:lift_place")
    counts = sorted(set(args.substeps) | {args.fine})
    rows: dict[int, dict] = {}
    for n in counts:
        t0 = time.perf_counter()
        scene = _scene(n)
        row = {"rate": raw_rate(scene, args.envs, args.threads, args.raw_steps, args.raw_repeats),
               "stance": pelvis_track(scene, push=False), "push": pelvis_track(scene, push=True),
               "hold": lift_hold(n, clip)}
        if args.checkpoint:
            row["eval"] = checkpoint_eval(n, args.checkpoint, args.episodes)
        rows[n] = row
        print(f"[{n} sub-steps measured in {time.perf_counter() - t0:.0f} s]", flush=True)

    fine = rows[args.fine]
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f} (1 min) at the end; {args.envs} envs, {args.threads} physics threads; "
          f"fine reference {args.fine} sub-steps")
    head = (f"{'N':>3} {'dt ms':>6} {'ctrl steps/s':>12} {'x vs ' + str(max(args.substeps)):>9} | {'stance z':>8} {'dev cm':>6} | "
            f"{'push z':>6} {'dev cm':>6} | {'hold frames':>11} {'drop cm':>7}")
    if args.checkpoint:
        head += f" | {'success':>7} {'inter.':>6}"
    print(head)
    faithful = []
    for n in counts:
        r = rows[n]
        dev_stance = 100 * np.abs(r["stance"] - fine["stance"]).max()
        dev_push = 100 * np.abs(r["push"] - fine["push"]).max()
        z_stance, z_push = r["stance"][-1, 2], r["push"][-1, 2]
        ok = ((z_stance > UPRIGHT_PELVIS_Z) == (fine["stance"][-1, 2] > UPRIGHT_PELVIS_Z)
              and (z_push > UPRIGHT_PELVIS_Z) == (fine["push"][-1, 2] > UPRIGHT_PELVIS_Z)
              and dev_stance <= 2.0 and dev_push <= 5.0
              and abs(r["hold"]["frames"] - fine["hold"]["frames"]) <= 0.1 * fine["hold"]["frames"]
              and abs(r["hold"]["object_drop_cm"] - fine["hold"]["object_drop_cm"]) <= 1.0)
        line = (f"{n:3d} {1000 / CONTROL_HZ / n:6.2f} {r['rate']:12.0f} {r['rate'] / rows[max(args.substeps)]['rate']:9.2f}"
                f" | {z_stance:8.3f} {dev_stance:6.2f} | {z_push:6.3f} {dev_push:6.2f} | "
                f"{r['hold']['frames']:11d} {r['hold']['object_drop_cm']:7.2f}")
        if args.checkpoint:
            ok = ok and r["eval"]["success_rate"] >= fine["eval"]["success_rate"] - 1 / 8
            line += f" | {r['eval']['success_rate']:7.2f} {r['eval']['interaction_success_rate']:6.2f}"
        print(line + ("  faithful" if ok else ""))
        if ok and n != args.fine:
            faithful.append(n)
    print(f"cheapest_faithful_substeps: {min(faithful) if faithful else 0}")


if __name__ == "__main__":
    main()

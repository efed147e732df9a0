"""The hold test: does the retargeted grasp keep the object when the robot plays the reference?

One episode from the default stand (with the warmup), zero residual (PD to the reference joints, grasp squeeze
included), the pelvis held on its reference by the assist wrench and the object left alone (no object assist).
Reported: how far the object falls below its reference while both hands must hold it, and whether the episode
ran to the end. A reference whose grasp cannot hold the object cannot be tracked by any policy.
"""

from __future__ import annotations

import copy

import torch


def hold_test(clip, env_cfg, embodiment, motion=None) -> dict:
    """{"object_drop_cm": max reference-minus-simulated object height while held, "frames_held": n,
    "completed": bool, "frames": frames played}."""
    from robot_hoi.rl.eval_cli import evaluation_settings
    from robot_hoi.tasks.interaction import factory

    cfg = copy.deepcopy(env_cfg)
    evaluation_settings(cfg, 1, 0)
    cfg.backend = "cpu"
    cfg.assist.enabled = True
    cfg.assist.object_kp = cfg.assist.object_kd = cfg.assist.object_kp_rot = cfg.assist.object_kd_rot = 0.0
    cfg.assist.object_gravity_share = 0.0
    env = factory.make_env([clip], cfg, embodiment, motions=[motion] if motion is not None else None)
    env.assist_level = 1.0
    env.reset()
    zero = torch.zeros(1, env.num_actions, device=env.device)
    drop, held, frames, completed = 0.0, 0, 0, False
    for _ in range(env.max_episode_length):
        ref_z = float(env.ref.object_pos[0, 2])
        both = bool(env.ref.hand_contact[0].all()) and int(env.warmup_left[0]) == 0
        _, _, terminated, truncated, _ = env.step(zero)
        frames += 1
        if terminated[0] or truncated[0]:
            completed = bool(truncated[0])
            break
        if both:
            held += 1
            drop = max(drop, ref_z - float(env.object_pos[0, 2]))
    return {"object_drop_cm": round(100 * drop, 2), "frames_held": held, "completed": completed, "frames": frames}

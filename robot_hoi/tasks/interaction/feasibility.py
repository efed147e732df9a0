"""The hold test: does the retargeted grasp keep the object when the robot plays the reference?

One episode from the reference state a few frames before both hands first hold the object (a stand start would
first have to survive the clip's walk-up), zero residual (PD to the reference joints, grasp squeeze included), the
pelvis held on its reference by the assist wrench and the object left alone (no object assist). Reported: how far
the object falls below its reference while both hands must hold it, how many held frames it lasted and what ended
it. A diagnostic, not a verdict: a policy adds residuals, and the embedded lift_place reference, which teachers
learn in under an hour, ends this test about half a second after the grip (the squeeze tilts the box).
"""

from __future__ import annotations

import copy

import torch


def hold_test(clip, env_cfg, embodiment, motion=None, lead_frames: int = 10) -> dict:
    """{"object_drop_cm": max reference-minus-simulated object height while held, "frames_held": n,
    "completed": bool, "frames": frames played, "start_frame", "first_held_frame", "ended_by": termination or
    None}; with no frame where both hands hold, {"frames_held": 0, "first_held_frame": None, ...}."""
    from robot_hoi.rl.eval_cli import evaluation_settings
    from robot_hoi.tasks.interaction import factory

    cfg = copy.deepcopy(env_cfg)
    evaluation_settings(cfg, 1, 0)
    cfg.backend = "cpu"
    cfg.assist.enabled = True
    cfg.assist.assisted_share = 1.0  # the root is held in every episode (training draws it for half of them)
    cfg.assist.object_kp = cfg.assist.object_kd = cfg.assist.object_kp_rot = cfg.assist.object_kd_rot = 0.0
    cfg.assist.object_gravity_share = 0.0
    cfg.assist.object_termination_margin = 0.0  # the evaluated object line
    cfg.init.stand_start_probability = 0.0
    cfg.init.joint_noise = 0.0
    env = factory.make_env([clip], cfg, embodiment, motions=[motion] if motion is not None else None)
    held_frames = env.ref_hand_contact.all(-1).nonzero().flatten()
    if held_frames.numel() == 0:
        return {"object_drop_cm": 0.0, "frames_held": 0, "completed": False, "frames": 0, "start_frame": None,
                "first_held_frame": None, "ended_by": None}
    first = int(held_frames[0])
    start = max(first - lead_frames, 0)
    span = max(int(env.clip_end[0] - env.clip_start[0]), 1)
    env.cfg.init.start_range = ((start + 0.5) / span,) * 2  # a reference start at exactly `start`
    env.assist_level = 1.0
    env.reset()
    zero = torch.zeros(1, env.num_actions, device=env.device)
    drop, held, frames, completed, ended_by = 0.0, 0, 0, False, None
    for _ in range(env.max_episode_length):
        ref_z = float(env.ref.object_pos[0, 2])
        both = bool(env.ref.hand_contact[0].all())
        _, _, terminated, truncated, info = env.step(zero)
        frames += 1
        if terminated[0] or truncated[0]:
            completed = bool(truncated[0])
            ended_by = next((k.split("/", 1)[1] for k, v in info["log"].items()
                             if k.startswith("Termination/") and float(v) > 0), None)
            break
        if both:
            held += 1
            drop = max(drop, ref_z - float(env.object_pos[0, 2]))
    return {"object_drop_cm": round(100 * drop, 2), "frames_held": held, "completed": completed, "frames": frames,
            "start_frame": start, "first_held_frame": first, "ended_by": ended_by}

"""The physics gate: can the robot keep the object by playing the reference, before a teacher trains on it?

One episode in the training scene (the task's physics, object and terminations), zero residual (PD to the
reference joints, grasp squeeze and load offsets included), the pelvis held on its reference by the assist
wrench and the object left alone (no object assist, no weight relief). It starts from the reference state a few
frames before a hand first has to hold the object (a stand start would first have to survive the clip's
walk-up) and runs to the clip's end. PASS: it reaches the end with no termination, so the object stayed within
the object termination line and every held segment (a run of frames where the clip says a hand touches the
object) stayed held by the training's contact rule; otherwise FAIL, with the frame, the reason and the held
segment it happened in. Figures kept from the earlier hold test: how far the object fell below its reference
while held, and how many held frames the replay lasted.

A teacher adds residuals to the reference, so PASS is not needed to learn a clip; FAIL says the reference itself
loses the object and a teacher must discover a grasp it does not contain. `robot-hoi train` refuses such a
reference unless told to train anyway.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import torch

from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env_cfg import RandomizationCfg
from robot_hoi.utils.threads import torch_threads

SIDES = ("left", "right")


def gate_config(env_cfg):
    """A copy of a task config set up for the gate: one env, reference start without noise, pelvis held, object
    free, the evaluated object line, no PSI and no domain randomisation. The gate judges the object and the held
    contacts only: the body conditions (link error, root height, interaction distance) are off, so a task's
    tightened body line does not fail a reference whose object is held."""
    cfg = copy.deepcopy(env_cfg)
    cfg.terminations = dataclasses.replace(cfg.terminations, max_mean_link_error=math.inf, min_root_height=-math.inf,
                                           max_interaction_distance_error=math.inf)
    cfg.num_envs = 1
    cfg.seed = 0
    cfg.backend = "cpu"
    cfg.psi.enabled = False
    cfg.randomization = RandomizationCfg()
    cfg.init.stand_start_probability = 0.0
    cfg.init.spawn_noise_xy = 0.0
    cfg.init.joint_noise = 0.0
    cfg.init.failure_weighted = False
    cfg.assist.enabled = True
    cfg.assist.initial_level = 1.0
    cfg.assist.assisted_share = 1.0  # the root is held in every episode (training draws it for half of them)
    cfg.assist.object_kp = cfg.assist.object_kd = cfg.assist.object_kp_rot = cfg.assist.object_kd_rot = 0.0
    cfg.assist.object_gravity_share = 0.0
    cfg.assist.object_termination_margin = 0.0  # the evaluated object line
    return cfg


def held_segments(hand_contact) -> list[dict]:
    """[{"hand": "left" | "right", "frames": [first, last]}] of the runs where a hand must touch the object,
    from a (T, 2) bool track (left, right), ordered by first frame."""
    need = torch.as_tensor(hand_contact, dtype=torch.bool).cpu()
    out = []
    for k, side in enumerate(SIDES):
        flags = torch.cat([torch.zeros(1, dtype=torch.bool), need[:, k], torch.zeros(1, dtype=torch.bool)]).int()
        edges = flags[1:] - flags[:-1]
        starts, ends = (edges == 1).nonzero().flatten(), (edges == -1).nonzero().flatten()
        out += [{"hand": side, "frames": [int(a), int(b) - 1]} for a, b in zip(starts, ends, strict=True)]
    return sorted(out, key=lambda s: (s["frames"][0], s["hand"]))


def physics_gate(clip, env_cfg, embodiment, motion=None, lead_frames: int = 10) -> dict:
    """The gate on one clip (its retarget `motion` when at hand, else retargeted with the task's settings); see
    `replay` for the result."""
    cfg = gate_config(env_cfg)
    # one env: torch's threads have nothing to share, and beside a training each small op waited on them (the gate
    # of sub8_largebox_000 took 1.6 s with 2 threads, 0.14 s with 1)
    with torch_threads(1):
        env = factory.make_env([clip], cfg, embodiment, motions=[motion] if motion is not None else None)
        return replay(env, lead_frames)


def replay(env, lead_frames: int = 10) -> dict:
    """Play the reference of a one-env, one-clip InteractionEnv built with `gate_config` from `lead_frames` before
    the first held frame to the clip's end. Returns {"verdict": "PASS" | "FAIL", "failure": None | {"frame",
    "reason", "hand", "segment", "object_error_cm"}, "segments", "frames_total", "start_frame",
    "first_held_frame", "frames" played, "frames_held", "object_drop_cm", "object_error_max_cm", "completed",
    "ended_by"}."""
    need = env.ref_hand_contact[int(env.clip_start[0]):int(env.clip_end[0]) + 1]
    segments = held_segments(need)
    held = need.any(-1).nonzero().flatten()
    first = int(held[0]) if held.numel() else None
    start = max((first or 0) - lead_frames, 0)
    span = max(int(env.clip_end[0] - env.clip_start[0]), 1)
    env.cfg.init.start_range = ((start + 0.5) / span,) * 2  # a reference start at exactly `start`
    env.assist_level = 1.0
    env.reset()
    zero = torch.zeros(1, env.num_actions, device=env.device)
    drop = error_max = 0.0
    frames = frames_held = 0
    loss = torch.zeros(2, dtype=torch.long)
    completed, ended_by, failure_error = False, None, None
    for _ in range(env.max_episode_length):
        ref_z = float(env.ref.object_pos[0, 2])
        holding = bool(env.ref.hand_contact[0].any())
        _, _, terminated, truncated, info = env.step(zero)
        frames += 1
        if terminated[0] or truncated[0]:
            completed = bool(truncated[0])
            ended_by = next((k.split("/", 1)[1] for k, v in info["log"].items()
                             if k.startswith("Termination/") and float(v) > 0), None)
            if "E_o_max_cm" in info.get("episode", {}):
                failure_error = float(info["episode"]["E_o_max_cm"][0])
            break
        error = float((env.object_points_world[0] - env.ref_object_points_world[0]).norm(dim=-1).mean())
        error_max = max(error_max, error)
        loss = env.contact_loss_frames[0].cpu()
        if holding:
            frames_held += 1
            drop = max(drop, ref_z - float(env.object_pos[0, 2]))
    failure = None
    if not completed:
        frame = start + frames
        hand = SIDES[int(loss.argmax())] if ended_by == "contact_lost" else None
        segment = next((s for s in segments if s["frames"][0] <= frame <= s["frames"][1]
                        and (hand is None or s["hand"] == hand)), None)
        if hand is not None and segment is None:  # counted from the segment the hand last had to hold
            segment = next((s for s in reversed(segments) if s["hand"] == hand and s["frames"][0] <= frame), None)
        failure = {"frame": frame, "reason": ended_by or "ended early", "hand": hand,
                   "segment": None if segment is None else f"{segment['hand']} {segment['frames'][0]}-"
                                                           f"{segment['frames'][1]}",
                   "object_error_cm": round(failure_error if failure_error is not None else 100 * error_max, 1)}
    return {"verdict": "PASS" if completed else "FAIL", "failure": failure, "segments": segments,
            "frames_total": span + 1, "start_frame": start, "first_held_frame": first, "frames": frames,
            "frames_held": frames_held, "object_drop_cm": round(100 * drop, 2),
            "object_error_max_cm": round(100 * max(error_max, (failure_error or 0.0) / 100), 2),
            "completed": completed, "ended_by": ended_by}


def format_verdict(gate: dict) -> str:
    """One line: the verdict and, on FAIL, what failed where."""
    played = f"frames {gate['start_frame']}-{gate['start_frame'] + gate['frames']} of {gate['frames_total']}"
    if gate["verdict"] == "PASS":
        return (f"PASS ({played}; {len(gate['segments'])} held segments kept; object error max "
                f"{gate['object_error_max_cm']} cm)")
    f = gate["failure"]
    where = f"in held segment {f['segment']}" if f["segment"] else "outside the held segments"
    return (f"FAIL: {f['reason']} at frame {f['frame']} {where} (object error {f['object_error_cm']} cm; "
            f"{played}, {gate['frames_held']} held frames kept)")


TABLE_HEADER = ("clip", "frames", "held segments", "verdict", "first failure", "retarget s", "gate s")


def format_table(rows: list[dict]) -> str:
    """The feasibility table of a folder of clips: rows {"clip", "frames", "gate" (physics_gate's dict) or
    "error" (why the clip could not be gated), "retarget_s", "gate_s"}."""
    cells = [TABLE_HEADER]
    for r in rows:
        gate = r.get("gate")
        if gate is None:
            cells.append((r["clip"], str(r.get("frames", "-")), "-", "ERROR", r.get("error", ""), "-", "-"))
            continue
        f = gate["failure"]
        first = "-" if f is None else f"{f['reason']} @ {f['frame']}" + (f" ({f['segment']})" if f["segment"] else "")
        cells.append((r["clip"], str(r["frames"]), str(len(gate["segments"])), gate["verdict"], first,
                      f"{r['retarget_s']:.1f}", f"{r['gate_s']:.1f}"))
    widths = [max(len(row[i]) for row in cells) for i in range(len(TABLE_HEADER))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in cells]
    passed = sum(1 for r in rows if r.get("gate") and r["gate"]["verdict"] == "PASS")
    return "\n".join([*lines, f"{passed} of {len(rows)} clips pass the physics gate"])


def gate_failures(clips: list, env_cfg, embodiment, caches: list) -> list[tuple[str, dict]]:
    """(clip name, physics_gate result) of each clip whose reference fails the gate. Each clip is retarget with
    the task's settings and cached in its `caches` entry (the folder its teacher reads its reference from; None:
    this process's cache only), so the teacher does not retarget it again."""
    options = factory.retarget_options(env_cfg)
    failed = []
    for clip, cache in zip(clips, caches, strict=True):
        gate = physics_gate(clip, env_cfg, embodiment, factory.load_or_retarget(clip, embodiment, cache, options))
        if gate["verdict"] != "PASS":
            failed.append((clip.name, gate))
    return failed

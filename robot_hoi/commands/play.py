"""`robot-hoi play CKPT|ONNX --video out.mp4`: watch a trained policy in the training simulation.

One episode from the default stand at the clip's start (eval's protocol: policy mean, no noise), rendered offscreen
with the reference motion as a translucent ghost robot and object, so tracking can be judged by eye. Takes a
teacher checkpoint (or its run folder) or an exported ONNX (teacher, student or untrained); a student checkpoint
plays through its export (robot-hoi export onnx CKPT).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from robot_hoi.data.cli_options import add_clip_options, clip_options


def register(subparsers) -> None:
    p = subparsers.add_parser("play", help="render a trained policy in the training simulation, with the "
                                           "reference as a ghost (mp4)", description=__doc__)
    p.add_argument("policy", metavar="CKPT|ONNX", help="teacher model_*.pt or its run folder, or an exported .onnx")
    p.add_argument("--video", required=True, metavar="OUT.mp4", help="video to write")
    p.add_argument("--clip", default=None, help="clip to track (file or embedded:<kind>; default: the policy's "
                                                "first training clip)")
    add_clip_options(p)
    p.add_argument("--seconds", type=float, default=None, metavar="S",
                   help="stop after S seconds of simulation (default: the whole clip)")
    p.add_argument("--seed", type=int, default=0, help="environment seed")
    p.add_argument("--embodiment", default="g1_inspire",
                   help="robot of an ONNX policy without an embodiment in its metadata")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robot_hoi.errors import UserError

    if Path(args.video).suffix != ".mp4":
        raise UserError(f"{args.video}: the video must end in .mp4")
    from robot_hoi.retarget.video import choose_gl_backend

    backend = choose_gl_backend()  # before mujoco is imported
    if backend is None:
        raise UserError("no offscreen OpenGL backend works here: install libEGL (MUJOCO_GL=egl) or OSMesa "
                        "(apt install libosmesa6, MUJOCO_GL=osmesa)")
    policy, env, group = (_onnx_policy(args) if Path(args.policy).suffix == ".onnx" else _checkpoint_policy(args))
    frames, outcome = rollout_frames(env, policy, group, args.seconds)
    from robot_hoi.sim.video import write_mp4

    write_mp4(args.video, frames, fps=1.0 / env.dt)
    print(f"wrote {args.video} ({outcome}; ghost = the reference; MUJOCO_GL={backend})")
    return 0


def _env_for(clip_source: str, env_cfg, embodiment, args, recorded_options=None, cache=None):
    from robot_hoi.rl.evaluation import evaluation_settings
    from robot_hoi.tasks.interaction import factory

    evaluation_settings(env_cfg, 1, args.seed)
    clip = factory.load_source(clip_source, clip_options(args, recorded_options))
    if clip.object is not None:
        print(f"{clip.name}: object {clip.object_name} from {clip.object.origin}")
    return factory.make_env([clip], env_cfg, embodiment, cache=cache)


def _checkpoint_policy(args):
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.errors import UserError
    from robot_hoi.rl.checkpoint import load_policy, resolve_checkpoint
    from robot_hoi.student.checkpoint import is_student_checkpoint
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import saved_env_cfg

    ckpt = resolve_checkpoint(args.policy)
    if is_student_checkpoint(ckpt):
        raise UserError(f"{ckpt}: a student checkpoint plays through its export: robot-hoi export onnx {ckpt} "
                        "-o student.onnx, then robot-hoi play student.onnx")
    model, _, _ = load_policy(ckpt)
    task = factory.read_task(ckpt)
    env_cfg = saved_env_cfg(task["env"], f"{ckpt} task")
    env = _env_for(args.clip or task["sources"][0], env_cfg, load_embodiment(task["embodiment"]), args,
                   task.get("clip_options"), cache=ckpt.parent / "references")
    if env.obs_dims["policy"] != model.num_actor_obs:
        raise UserError(f"{ckpt}: policy expects {model.num_actor_obs} observations, the task gives "
                        f"{env.obs_dims['policy']}")
    return model.act_inference, env, "policy"


def _onnx_policy(args):
    import numpy as np
    import onnxruntime as ort
    import torch

    from robot_hoi.commands.train import TASK_CONFIG
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.errors import UserError
    from robot_hoi.export.onnx_export import check_onnx_file
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.tasks.interaction.mdp.observations import DEFAULT_STUDENT_TERMS
    from robot_hoi.utils.config import load_yaml_dataclass

    meta = {k: json.loads(v) for k, v in check_onnx_file(args.policy).items() if k != "robot_hoi.version"}
    env_cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)
    group = "policy" if meta.get("policy_kind") == "teacher" else "student"
    if group == "student":
        env_cfg.student_obs_terms = tuple(s["name"] for s in meta.get("obs_spec", [])) or DEFAULT_STUDENT_TERMS
        env_cfg.student_keyframes = tuple(meta.get("keyframes", env_cfg.student_keyframes))
    env_cfg.action_offset = "reference" if meta.get("action_offset_mode") == "reference" else "default"
    env_cfg.warmup_frames = int(meta.get("warmup_frames", env_cfg.warmup_frames))
    clips = (meta.get("data") or {}).get("clips") or [{}]
    source = args.clip or clips[0].get("source")
    if not source:
        raise UserError(f"{args.policy}: its metadata names no clip; pass --clip")
    env = _env_for(source, env_cfg, load_embodiment(meta.get("embodiment") or args.embodiment), args)
    session = ort.InferenceSession(args.policy, providers=["CPUExecutionProvider"])
    name, width = session.get_inputs()[0].name, session.get_inputs()[0].shape[-1]
    if width != env.obs_dims[group]:
        raise UserError(f"{args.policy}: expects {width} observations, the training env gives {env.obs_dims[group]} "
                        f"for '{group}'")

    def act(obs):
        return torch.as_tensor(session.run(None, {name: obs.cpu().numpy().astype(np.float32)})[0])

    return act, env, group


def ghost_qpos(env, qpos):
    """The full-state qpos of the reference at env 0's current frame (robot and object)."""
    ghost = qpos.copy()
    index, layout = int(env.ref_index[0]), env.layout
    ghost[:layout.robot_nq] = env.ref_robot_qpos[index].cpu().numpy()
    ghost[layout.object_qpos:layout.object_qpos + 3] = env.ref_object_pos[index].cpu().numpy()
    ghost[layout.object_qpos + 3:layout.object_qpos + 7] = env.ref_object_quat[index].cpu().numpy()
    return ghost


def rollout_frames(env, act, group: str, seconds: float | None):
    """Run env 0 until its episode ends (or `seconds`); returns (frames, outcome line)."""
    import torch

    from robot_hoi.sim.video import StateRenderer

    limit = env.max_episode_length + 1 if seconds is None else max(int(seconds / env.dt), 1)
    frames, outcome = [], f"stopped after {limit * env.dt:.1f} s"
    obs = env.reset()
    with StateRenderer(env.scene.model) as renderer, torch.no_grad():
        for step in range(limit):
            qpos = env.backend.qpos[0].cpu().numpy().astype(float)
            frames.append(renderer.render(qpos, ghost_qpos=ghost_qpos(env, qpos)))
            obs, _, terminated, truncated, extras = env.step(act(obs[group]))
            if bool(terminated[0] | truncated[0]):
                reasons = [k.split("/", 1)[1] for k, v in extras.get("log", {}).items()
                           if k.startswith("Termination/") and v > 0]
                ended = f"terminated: {', '.join(reasons)}" if bool(terminated[0]) else "reached the end of the clip"
                outcome = f"{ended} after {(step + 1) * env.dt:.1f} s"
                break
    return frames, outcome

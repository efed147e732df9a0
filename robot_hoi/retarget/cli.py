"""`robot-hoi retarget [CLIP] -o OUT.npz [--video OUT.mp4] [--json]`: kinematic IK retarget onto the robot."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from robot_hoi.data.cli_options import add_clip_options, clip_options


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "retarget",
        help="kinematic IK retarget of an HOI clip onto the robot (reference motion for the teachers)",
        description="Map a human-object clip onto the robot: scaled body, real-size object, hands anchored to "
        "the object, per-frame damped-least-squares IK. Writes OUT.npz + OUT.json and prints the residuals.",
    )
    p.add_argument("clip", nargs="?", help="clip file (.pt InterMimic or .npz native) or embedded:KIND; default: the embedded "
                   "stand-lift-place clip (embedded:lift_place)")
    p.add_argument("--embodiment", default="g1_inspire", help="embodiment name or YAML path (default g1_inspire)")
    p.add_argument("-o", "--output", required=True, help="motion file to write (.npz; a .json sidecar goes next to it)")
    p.add_argument("--video", help="also write an mp4 of the retargeted motion")
    p.add_argument("--video-backend", choices=("auto", "mujoco", "matplotlib"), default="auto",
                   help="auto: MuJoCo offscreen (EGL, then OSMesa) if it works, else a matplotlib stick figure")
    p.add_argument("--pretty", action="store_true", help="video with Unitree meshes and shadows (slow on CPU GL)")
    p.add_argument("--video-stride", type=int, default=1, help="render every Nth frame (default 1)")
    p.add_argument("--scale", type=float, help="human->robot scale (default robot_height / subject height)")
    p.add_argument("--anchor-mode", choices=("distance", "contact"), default="distance",
                   help="anchor weights from the distance to the object (default) or from the clip's contact labels")
    p.add_argument("--leg-loads", action="store_true",
                   help="offset the leg PD targets by the torques that carry the body on the feet in contact "
                        "(a crouch holds its pose; walking replays sag ~3x less but do not last longer); training "
                        "uses it with --set env.retarget_leg_loads=true")
    p.add_argument("--dynamics", action="store_true",
                   help="offset the PD targets by the torques that drive the motion and cancel the servos' damping "
                        "(inverse dynamics along the reference); training: --set env.retarget_dynamics=true")
    p.add_argument("--finger-closure", type=float,
                   help="fraction of the fingers' stroke closed while a hand holds (default 0.6; 0: flat hands that "
                        "still squeeze); training: --set env.retarget_finger_closure=F")
    p.add_argument("--squeeze-toward", choices=("other_hand", "surface"), default=None,
                   help="where a holding hand's PD targets squeeze: toward the other hand (default; a two-hand grip) "
                        "or into the object's nearest face (a push); training: "
                        "--set env.retarget_squeeze_toward=surface")
    p.add_argument("--squeeze-depth", type=float, default=None, metavar="M",
                   help="how far past the surface a holding hand's PD targets squeeze (default 0.06 m); training: "
                        "--set env.retarget_squeeze_depth=M")
    p.add_argument("--fingertip-underside-reach", type=float, default=None, metavar="M",
                   help="fingertip targets at most M under an underside of the object (a tabletop) move up onto it "
                        "(0.15 reaches them; default 0: off); training: --set env.retarget_fingertip_underside_reach=M")
    add_clip_options(p, "--objects-dir")  # --objects-dir: the old spelling, kept working
    p.add_argument("--object-collision", choices=("hull", "decomposed"), default=None,
                   help="what the object collides as: its convex hull or its convex pieces (CoACD; a hand reaches "
                        "under a table's top); the IK keeps the hands out of it (default: the task's "
                        "env.object_collision, configs/tasks/interaction.yaml)")
    p.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robot_hoi.errors import UserError

    out = Path(args.output)
    if out.suffix != ".npz":
        raise UserError(f"{out}: the motion file must end in .npz")
    if args.video and Path(args.video).suffix != ".mp4":
        raise UserError(f"{args.video}: the video must end in .mp4")
    if args.video_stride < 1:
        raise UserError(f"--video-stride must be >= 1, got {args.video_stride}")
    if args.video and args.video_backend != "matplotlib":
        from robot_hoi.retarget.video import choose_gl_backend

        choose_gl_backend()  # must run before mujoco is imported

    from dataclasses import replace

    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.retarget.executable import check_squeeze_depth
    from robot_hoi.retarget.hands import check_closure
    from robot_hoi.retarget.pipeline import RetargetOptions, retarget_clip
    from robot_hoi.retarget.report import build_report, format_report
    from robot_hoi.rl.eval_cli import TASK_CONFIG
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.utils.config import load_yaml_dataclass

    cfg = load_embodiment(args.embodiment)
    clip = _load(args)
    model = build_model(cfg)
    options = RetargetOptions()
    task = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)  # the task's settings
    task.object_collision = args.object_collision or task.object_collision  # the hold test collides with it too
    options = replace(options, mapping=replace(options.mapping, anchor_mode=args.anchor_mode,
                                               object_collision=task.object_collision),
                      executable=replace(options.executable, compensate_leg_loads=args.leg_loads,
                                         compensate_dynamics=args.dynamics))
    if args.squeeze_toward is not None:
        options = replace(options, executable=replace(options.executable, squeeze_toward=args.squeeze_toward))
    if args.squeeze_depth is not None:
        depth = check_squeeze_depth(args.squeeze_depth, "--squeeze-depth")
        options = replace(options, executable=replace(options.executable, squeeze_depth=depth))
    if args.fingertip_underside_reach is not None:
        if args.fingertip_underside_reach < 0:
            raise UserError(f"--fingertip-underside-reach must be >= 0 m, got {args.fingertip_underside_reach}")
        options = replace(options, mapping=replace(options.mapping,
                                                   fingertip_underside_reach=args.fingertip_underside_reach))
    if args.finger_closure is not None:
        closure = check_closure(args.finger_closure, "--finger-closure")
        options = replace(options, grasp=replace(options.grasp, closure=closure))
    result = retarget_clip(clip, cfg, model, scale=args.scale, options=options)
    report = build_report(result)
    report["clip"] = clip.name
    report["feasibility"] = _feasibility(clip, cfg, result.motion, task)
    result.motion.meta["report"] = report
    result.motion.meta["feasibility"] = report["feasibility"]
    npz, sidecar = result.motion.save(out)
    report["output"] = {"motion": str(npz), "sidecar": str(sidecar)}
    if args.video:
        from robot_hoi.retarget.video import write_video

        renderer = write_video(result.motion, cfg, model, args.video, clip.object, backend=args.video_backend,
                               stride=args.video_stride, pretty=args.pretty)
        report["video"] = {"path": str(args.video), "renderer": renderer}
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        print(f"clip {clip.name}")
        print(format_report(report))
        print(format_feasibility(report["feasibility"]))
        print(f"wrote {npz} and {sidecar}")
        if args.video:
            print(f"wrote {args.video} (rendered with {report['video']['renderer']})")
    return 0


def _feasibility(clip, cfg, motion, task) -> dict:
    """Can the robot execute it: kinematic figures and the hold test (a root-held replay in the training scene)."""
    from robot_hoi.tasks.interaction.factory import kinematic_report
    from robot_hoi.tasks.interaction.feasibility import hold_test

    report = kinematic_report(motion, cfg)
    report["hold_test"] = hold_test(clip, task, cfg, motion)
    return report


def format_feasibility(f: dict) -> str:
    slide = ", ".join(f"{k.split('_')[0]} {v} cm" for k, v in f["foot_slide_cm"].items())
    hold = f.get("hold_test")
    lines = [f"feasibility: foot slide in contact {slide}; CoM outside support in "
             f"{100 * f['com_outside_support_fraction']:.0f}% of frames; joint speed peak "
             f"{f['joint_speed_peak_rad_s']} rad/s (p99 {f['joint_speed_p99_rad_s']})"]
    if "self_penetration_cm" in f:
        pairs = ", ".join(f"{k} {v} cm" for k, v in f["self_penetration_pairs"].items()) or "none over 1 cm"
        lines.append(f"self-penetration (self-collision on): deepest {f['self_penetration_cm']} cm, "
                     f"{100 * f['self_penetration_fraction']:.0f}% of frames over 1 cm ({pairs})")
    if hold and hold.get("first_held_frame") is None:
        lines.append("hold test: no frame where both hands hold the object")
    elif hold:
        end = "ran to the end" if hold["completed"] else f"ended by {hold.get('ended_by') or 'a termination'}"
        lines.append(f"hold test (from frame {hold.get('start_frame')}, both hands hold from frame "
                     f"{hold['first_held_frame']}; root held, zero residual): object drop {hold['object_drop_cm']} cm "
                     f"over {hold['frames_held']} held frames; {end} after {hold['frames']} frames")
    return "\n".join(lines)


def _load(args: argparse.Namespace):
    from robot_hoi.tasks.interaction.factory import DEFAULT_SOURCE, load_source

    return load_source(args.clip or DEFAULT_SOURCE, clip_options(args))
